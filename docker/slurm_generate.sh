#!/bin/bash
# Example Slurm job: generate a dataset on a cluster. Submit from the repository root after
# `make setup-solver` (or inside the solver image with your site's container runtime):
#     sbatch docker/slurm_generate.sh data_spec/scenes/scene1_base.toml runs/data/scene1
#SBATCH --job-name=liverfem-generate
#SBATCH --nodes=2
#SBATCH --ntasks-per-node=32
#SBATCH --cpus-per-task=1
#SBATCH --time=04:00:00
#SBATCH --output=liverfem-%j.log
set -euo pipefail
SCENE=${1:?scene file}
OUT=${2:?output directory}
RANKS_PER_SIM=${RANKS_PER_SIM:-1}   # ranks that share one simulation (domain decomposition)
export OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1
# Resumable: re-submitting the same job skips the shards that are already valid.
srun --mpi=pmix .venv-solver/bin/python -m fem_sim generate "$SCENE" --out "$OUT" \
    --ranks-per-sim "$RANKS_PER_SIM"
# Without srun's PMIx support use: mpirun -n "$SLURM_NTASKS" .venv-solver/bin/python -m fem_sim ...
