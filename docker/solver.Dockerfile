# Solver image: Debian bookworm + dolfinx 0.5.2 + the project, set up exactly as `make setup-solver`.
# Build from the repository root:  docker build -f docker/solver.Dockerfile -t liverfem-solver .
# Run a batch:  docker run --rm -v $PWD/runs:/opt/liverfem/runs liverfem-solver \
#                 mpirun -n 4 .venv-solver/bin/python -m fem_sim generate \
#                 data_spec/scenes/scene1_base.toml --out runs/data/scene1
FROM debian:bookworm
ENV DEBIAN_FRONTEND=noninteractive \
    OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OPENBLAS_NUM_THREADS=1
WORKDIR /opt/liverfem
# The package list is shared with the Makefile: requirements/debian-packages.txt.
COPY requirements/debian-packages.txt requirements/
COPY scripts/setup_system.sh scripts/
RUN bash scripts/setup_system.sh requirements/debian-packages.txt && rm -rf /var/lib/apt/lists/*
COPY . .
RUN make setup-solver
CMD ["bash"]
