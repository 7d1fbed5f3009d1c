# liverfem: every set-up step lives here. `make demo` and `make test` run `setup` themselves.
# Two interpreters: Debian's /usr/bin/python3 with dolfinx 0.5.2 (numpy 1.24) for the solver,
# and a separate virtualenv with JAX (numpy 2) for the trainer. See README.md.
SHELL := /bin/bash
.DEFAULT_GOAL := help

SYS_PY      := /usr/bin/python3
SOLVER_VENV := .venv-solver
TRAIN_VENV  := .venv-train
SPY         := $(SOLVER_VENV)/bin/python
TPY         := $(TRAIN_VENV)/bin/python

SCENE ?= data_spec/scenes/demo_scene1.toml
NP    ?= 2
R     ?= 1
OUT   ?= runs/data/$(basename $(notdir $(SCENE)))
LIVERS := ../shared/data/livers/real
DATA  ?= $(OUT)
RUN   ?= runs/train/$(basename $(notdir $(SCENE)))
TESTS ?=

# mpirun refuses root unless told; BLAS threads would fight the MPI ranks for the 2 cores.
export OMPI_ALLOW_RUN_AS_ROOT := 1
export OMPI_ALLOW_RUN_AS_ROOT_CONFIRM := 1
export OMPI_MCA_rmaps_base_oversubscribe := 1
export OPENBLAS_NUM_THREADS ?= 1
export OMP_NUM_THREADS ?= 1
# OpenBLAS' kernels from the CPU's instruction sets (fem_sim/cpu_blas.py: VMs that hide the CPU
# model otherwise get the SSE3 kernels, about 2x slower factorisations); a value set is kept.
BLAS_CORE := $(shell $(SYS_PY) fem_sim/cpu_blas.py 2>/dev/null)
ifneq ($(BLAS_CORE),)
export OPENBLAS_CORETYPE ?= $(BLAS_CORE)
endif
MPIRUN := mpirun -n $(NP)

.PHONY: help setup setup-system setup-solver setup-trainer demo test test-solver test-trainer \
        test-extremes extremes-doc \
        dataset train population table4 bench bench-solver bench-throughput bench-inference \
        bench-population truth evaluate patient patient-args liver liver-args manipulate scene4-real bench-patient bench-patient-grasps bench-surgical bench-ready bench-grasp-rest tradeoff-fem tradeoff-surrogate bench-realtime docs lint \
        bench-viewer docs-manipulator viewer \
        clean lock-trainer

help:
	@echo "make demo     set up, generate a small dataset on the embedded liver, train, report"
	@echo "make test     set up and run the whole test suite"
	@echo "make test-extremes   stability at the extremes (part of make test)"
	@echo "make setup    install Debian packages (root) and create $(SOLVER_VENV), $(TRAIN_VENV)"
	@echo "make dataset  SCENE=... NP=... R=... OUT=...   generate a dataset with mpirun"
	@echo "make train    SCENE=... DATA=... RUN=...       train the surrogate on a dataset"
	@echo "make population SCENE=... OUT=...  CPD + PCA shape coefficients (scene 4)"
	@echo "make bench    solver, throughput and inference benchmarks -> docs/ (about half an hour)"
	@echo "make truth RUN=... LIVER=... SCENE=... OUT=...   FE truth of a liver a model never saw"
	@echo "make evaluate RUN=... DATA=... [LIVER=...]   a model against a dataset it never saw"
	@echo "make patient LIVER=... MODEL=... [K=40]   a new patient's own model (docs/patient.md)"
	@echo "make liver LIVER=... MODEL=... AT=\"X Y Z FX FY FZ\"   a new liver over its own Green's function, seconds"
	@echo "make manipulate LIVER=... [MODEL=...]   the manipulator on that liver (a window)"
	@echo "           (or GRASP=\"X Y Z DX DY DZ\": a 10 mm patch moved, the field and the tool's force)"
	@echo "make bench-surgical   grasps to 40 mm, forces to 4 N on the validation livers -> docs/surgical_loads.md"
	@echo "make bench-ready     make liver GRASP=... timed from each validation liver's file -> the same"
	@echo "make bench-grasp-rest   the network over the grasp's base, cross-validated; the model of grasps"
	@echo "make bench-patient-grasps   make patient LOAD=grasp on the validation livers -> docs/patient_grasps.md"
	@echo "make tradeoff-fem   FEM speed/accuracy price list -> docs/tradeoff_fem.md (long, resumable)"
	@echo "make tradeoff-surrogate   surrogate price list + error budget -> docs/ (long, resumable)"
	@echo "make table4   the paper's Table 4, scenes 1-4 -> docs/table4.md (long, resumable)"
	@echo "make bench-realtime   real-time surrogate designs -> docs/realtime.md (long, resumable)"
	@echo "make viewer   RUN=...   the liver manipulator on a trained run (a window)"
	@echo "make bench-viewer   manipulator frame rate, whole liver and surface -> docs/viewer.md"
	@echo "make docs     regenerate docs/phantoms.png"
	@echo "make docs-manipulator   docs/manipulator.gif, docs/compare.png from make demo's run"
	@echo "make lint     ruff";  echo "make clean    remove environments and outputs"

setup: setup-solver setup-trainer

setup-system:
	@bash scripts/setup_system.sh requirements/debian-packages.txt
	@bash scripts/setup_system.sh requirements/debian-packages-trainer.txt

# The solver venv sees Debian's packages (dolfinx, petsc4py, numpy 1.24); pip is constrained so
# that nothing installed into it can replace numpy. The project is installed editable into each
# environment (pip install -e . --no-deps: the versions come from Debian and the lock files).
$(SOLVER_VENV)/.stamp: requirements/debian-packages.txt requirements/solver-extras.txt \
                       requirements/solver-constraints.txt pyproject.toml
	@bash scripts/setup_system.sh requirements/debian-packages.txt
	$(SYS_PY) -m venv --system-site-packages $(SOLVER_VENV)
	$(SPY) -m pip install -q --disable-pip-version-check -c requirements/solver-constraints.txt \
	    -r requirements/solver-extras.txt
	$(SPY) -m pip install -q --disable-pip-version-check --no-deps --no-build-isolation -e .
	$(SPY) -c "import dolfinx, numpy; assert numpy.__version__.startswith('1.'), numpy.__version__"
	@touch $@

setup-solver: $(SOLVER_VENV)/.stamp

$(TRAIN_VENV)/.stamp: requirements/trainer.lock requirements/test.lock \
                      requirements/debian-packages-trainer.txt pyproject.toml
	@bash scripts/setup_system.sh requirements/debian-packages-trainer.txt
	$(SYS_PY) -m venv $(TRAIN_VENV)
	$(TPY) -m pip install -q --disable-pip-version-check -r requirements/trainer.lock \
	    -r requirements/test.lock
	$(TPY) -m pip install -q --disable-pip-version-check --no-deps -e .
	$(TPY) -c "import jax, flax, optax, numpy; assert int(numpy.__version__[0]) >= 2"
	@touch $@

setup-trainer: $(TRAIN_VENV)/.stamp

# Re-pin the trainer environment from requirements/trainer.in (maintainers only).
lock-trainer:
	rm -rf /tmp/liverfem-lock && $(SYS_PY) -m venv /tmp/liverfem-lock
	/tmp/liverfem-lock/bin/pip install -q -r requirements/trainer.in
	{ head -2 requirements/trainer.lock; /tmp/liverfem-lock/bin/pip freeze; } > requirements/trainer.lock.new
	mv requirements/trainer.lock.new requirements/trainer.lock

demo: setup
	@bash scripts/demo.sh "$(SPY)" "$(TPY)" "$(NP)"

dataset: setup-solver
	$(MPIRUN) $(SPY) -m fem_sim generate $(SCENE) --out $(OUT) --ranks-per-sim $(R)

train: setup-trainer
	$(TPY) -m surrogate train --data $(DATA) --run $(RUN)

test: setup test-solver test-extremes test-trainer

test-solver: setup-solver
	bash scripts/run_pytest.sh $(SPY) tests/common tests/data_spec tests/liverviz tests/fem_sim tests/reliability -q --durations=12 $(TESTS)

# Stability at the extremes: every case must converge with a physically right answer.
test-extremes: setup-solver
	bash scripts/run_pytest.sh $(SPY) tests/extremes -q --durations=5 $(TESTS)

extremes-doc: setup-solver
	$(SPY) -m scripts.extremes_doc docs/extremes.md

# A small real dataset (fem_sim) for the trainer's end-to-end test; regenerated only if missing.
TEST_DATA := runs/test-data/ci_scene1
$(TEST_DATA)/.done: data_spec/scenes/ci_scene1.toml | setup-solver
	$(MPIRUN) $(SPY) -m fem_sim generate $< --out $(TEST_DATA) --no-progress
	@touch $@

# A population of 6 livers for predict-liver's tests (data_spec/scenes/ci_scene4.toml), with
# each liver's small-strain base (tests/surrogate/test_population_linear.py).
TEST_DATA4 := runs/test-data/ci_scene4
$(TEST_DATA4)/.done: data_spec/scenes/ci_scene4.toml | setup-solver
	$(MPIRUN) $(SPY) -m fem_sim generate $< --out $(TEST_DATA4) --no-progress
	$(SPY) -m fem_sim linear --population $(TEST_DATA4) --order 2
	@touch $@

# Three real livers as a file population (data_spec/scenes/ci_livers.toml, ../shared).
TEST_LIVERS := runs/test-data/ci_livers
$(TEST_LIVERS)/.done: data_spec/scenes/ci_livers.toml | setup-solver
	$(MPIRUN) $(SPY) -m fem_sim generate $< --out $(TEST_LIVERS) --no-progress
	$(SPY) -m fem_sim linear --population $(TEST_LIVERS) --order 2
	@touch $@

# Six phantoms grasped (data_spec/scenes/ci_grasp.toml) with each liver's small-strain
# responses (order 1: a grasp's), for the trainer's grasp tests (tests/surrogate/test_grasp.py).
TEST_GRASP := runs/test-data/ci_grasp
$(TEST_GRASP)/.done: data_spec/scenes/ci_grasp.toml | setup-solver
	$(MPIRUN) $(SPY) -m fem_sim generate $< --out $(TEST_GRASP) --no-progress
	$(SPY) -m fem_sim linear --population $(TEST_GRASP) --order 1
	@touch $@

# The shipped model's card measured again (tests/surrogate/test_shipped_model.py): the FE
# truth of bench/surgical_loads.py's three grasps on the validation liver Amos-054.
TEST_SHIPPED := runs/test-data/shipped/Amos-054.npz
$(TEST_SHIPPED): fem_sim/batch/grasp_truth.py | setup-solver
	$(SPY) -m fem_sim.batch.grasp_truth $(LIVERS)/Amos-054.obj \
	    --scene data_spec/scenes/scene4_livers.toml --grasps 3 --out $@

# The shipped model of forces' card measured again (the same test): the FE truth of three of
# the scene's 0.4 N forces on Amos-054 with the model's boundary condition, and their base.
TEST_FORCES := runs/test-data/shipped/forces-Amos-054
$(TEST_FORCES)/.done: models/scene4_forces/model/params.npz | setup
	rm -rf $(@D)
	$(SPY) -m fem_sim mesh $(LIVERS)/Amos-054.obj --scene data_spec/scenes/scene4_livers.toml \
	    --out $(@D)/mesh.h5 --no-picture
	$(TPY) -m surrogate truth-scene models/scene4_forces $(LIVERS)/Amos-054.obj --sims 3 \
	    --scene data_spec/scenes/scene4_livers.toml --out $(@D)/scene.toml --mesh $(@D)/mesh.h5
	$(MPIRUN) $(SPY) -m fem_sim generate $(@D)/scene.toml --out $(@D)/data --no-progress
	$(SPY) -m fem_sim linear $(@D)/scene.toml --out $(@D)/data --order 1
	@touch $@

# A tiny new patient end to end: a population model trained on the three livers, make patient
# on a fourth (20 FE simulations to adapt on, 6 held out); tests/surrogate/test_patient.py.
# One of the three meshed as make liver meshes a liver file (tests/surrogate/test_placement.py).
TEST_PATIENT := runs/test-data/ci_patient
$(TEST_PATIENT)/.done: $(TEST_LIVERS)/.done | setup
	rm -rf $(TEST_PATIENT)
	$(TPY) -m surrogate train --data $(TEST_LIVERS) --run $(TEST_PATIENT)/population \
	    folds=3 evaluate_folds=1 epochs=60 hidden=[64,64] ensemble=1 modes=16 > /dev/null
	$(MAKE) --no-print-directory patient LIVER=$(LIVERS)/Amos-004.obj \
	    MODEL=$(TEST_PATIENT)/population PSCENE=$(TEST_LIVERS)/scene.toml K=20 HELD=6 \
	    PATIENT=$(TEST_PATIENT)
	$(SPY) -m fem_sim mesh $(LIVERS)/Amos-005.obj --scene $(TEST_LIVERS)/scene.toml \
	    --out $(TEST_PATIENT)/member/Amos-005.h5 --no-picture
	@touch $@

# A patient's model of grasps end to end (tests/surrogate/test_patient_grasp.py): make patient
# LOAD=grasp with the shipped model of grasps on Amos-054, 8 grasps to adapt on and 3 held
# out around the site bench/patient_grasps.py grasps it at (grasp_site).
TEST_PGRASP := runs/test-data/ci_patient_grasp
$(TEST_PGRASP)/.done: models/scene4_grasp/model/params.npz models/scene4_grasp/model/model.json \
                      | setup
	rm -rf $(@D)
	$(MAKE) --no-print-directory patient LOAD=grasp LIVER=$(LIVERS)/Amos-054.obj K=8 HELD=3 \
	    SITE="22.51 -7.86 -25.35" PATIENT=$(@D)
	@touch $@

test-trainer: setup-trainer $(TEST_DATA)/.done $(TEST_DATA4)/.done $(TEST_PATIENT)/.done \
              $(TEST_GRASP)/.done $(TEST_SHIPPED) $(TEST_FORCES)/.done $(TEST_PGRASP)/.done
	$(TRAIN_VENV)/bin/ruff check .
	LIVERFEM_TEST_DATASET=$(TEST_DATA) LIVERFEM_TEST_DATASET4=$(TEST_DATA4) \
	    LIVERFEM_TEST_PATIENT=$(TEST_PATIENT) LIVERFEM_TEST_LIVERS=$(TEST_LIVERS) \
	    LIVERFEM_TEST_GRASP=$(TEST_GRASP) LIVERFEM_TEST_SHIPPED=$(TEST_SHIPPED) \
	    LIVERFEM_TEST_FORCES=$(TEST_FORCES) LIVERFEM_TEST_PATIENT_GRASP=$(TEST_PGRASP) \
	    bash scripts/run_pytest.sh $(TPY) tests/data_spec tests/liverviz tests/liverreg \
	    tests/surrogate tests/reliability tests/common/test_environments.py -q --durations=12 $(TESTS)

# The benchmarks that fit two cores in about half an hour, each writing its report under docs/;
# the long studies (table4, tradeoff-*, bench-realtime, bench-viewer) are targets of their own.
bench: bench-solver bench-throughput bench-inference

bench-solver: setup-solver  # needs ../shared/data/livers/sofa_liver.vtk
	OMP_NUM_THREADS=2 OPENBLAS_NUM_THREADS=2 $(SPY) bench/bench_hard.py --h 5 --batch 3 --textbook

bench-throughput: setup-solver
	$(SPY) bench/bench_throughput.py

bench-inference: setup-trainer
	$(TPY) bench/bench_surrogate.py

bench-population: setup-solver
	$(SPY) bench/bench_population.py

# A liver a model never saw: the scene of its FE truth with the model's boundary condition
# (trainer environment), solved under mpirun (solver environment), then the model against it.
LIVER ?=
TRUTH_SIMS ?= 60
truth: setup
	@test -n "$(LIVER)" || { echo "make truth: LIVER=file RUN=run SCENE=population scene OUT=dir"; exit 2; }
	$(SPY) -m fem_sim mesh $(LIVER) --scene $(SCENE) --out $(OUT)/mesh.h5 --no-picture
	$(TPY) -m surrogate truth-scene $(RUN) $(LIVER) --scene $(SCENE) --sims $(TRUTH_SIMS) \
	    --out $(OUT)/scene.toml --mesh $(OUT)/mesh.h5
	$(MPIRUN) $(SPY) -m fem_sim generate $(OUT)/scene.toml --out $(OUT)/data
	$(TPY) -m surrogate evaluate $(RUN) $(OUT)/data --liver $(LIVER) --mesh $(OUT)/mesh.h5 \
	    --out $(OUT)/evaluation.json

# A new patient (docs/patient.md): the population model MODEL (a run) placed on the liver file
# LIVER, K FE simulations on the patient's own mesh with the model's boundary condition (solver
# environment, mpirun), the liver's small-strain responses to them and to SYNTHETIC drawn
# loads (fem_sim linear: one factorisation), those corrected with the K simulations and
# distilled into the patient's own model, $(PATIENT)/run/model (trainer environment), which
# carries the liver's Green's function (a unit response at each surface node: the exact
# small-strain part of any nodal load) and learns only the rest (docs/load_expansion.md;
# GREEN=0 leaves it out: less accurate, a shorter fem_sim linear on a large mesh). PSCENE:
# the population scene MODEL was trained on (its loads, material, steps and solver). HELD more simulations are solved and kept
# out of the adaptation (to measure the patient model on); FRAME: the liver file's frame;
# ADAPT: more options of surrogate adapt (ADAPT=--tune fine-tunes the population network);
# ORDER=1: the small-strain responses without their second-order terms (docs/load_expansion.md);
# REST: a population model of what each liver's small-strain base misses (config
# population_linear, docs/scene4_real.md), added to the patient's base (a MODEL of that config
# is its own REST). K=0: the patient's small-strain responses (and REST) alone; one FE
# simulation is still solved (the scene needs one: it names the mesh and the dataset), none
# adapts the model. LOAD=grasp: a patient's model of grasps (surrogate/patient/grasps.py):
# MODEL a model of grasps (default: the shipped one), K grasps of GSCENE on the patient's
# mesh, its Green's function, and the model's force and field corrected with them
# ($(PATIENT)/run/grasp_patient.npz; predict-liver and the manipulator take --patient).
# SITE="X Y Z": the K grasps (and HELD) drawn within 20 mm of that point (mm, the liver
# file's frame): a patient's planned grasp, where the corrections are measured to help.
K ?= 40
SITE ?=
LOAD ?= force
GSCENE ?= data_spec/scenes/scene4_grasp.toml
HELD ?= 0
FRAME ?=
ADAPT ?=
MODEL ?=
PSCENE ?= data_spec/scenes/scene4_livers.toml
REST ?=
SYNTHETIC ?= 600
ORDER ?= 2
GREEN ?= 1
PATIENT ?= runs/patient/$(basename $(notdir $(LIVER)))
P_GRASP = $(filter grasp,$(LOAD))
P_MODEL = $(or $(MODEL),$(if $(P_GRASP),$(SHIPPED_GRASP)))
P_SCENE = $(if $(P_GRASP),$(GSCENE),$(PSCENE))
patient-args:
	@$(SYS_PY) scripts/make_args.py patient LIVER="$(LIVER)" MODEL="$(P_MODEL)" K="$(K)" \
	    HELD="$(HELD)" SYNTHETIC="$(SYNTHETIC)" ORDER="$(ORDER)" GREEN="$(GREEN)" \
	    PSCENE="$(P_SCENE)" FRAME="$(FRAME)" LOAD="$(LOAD)" SITE="$(SITE)"
patient: patient-args setup
	$(SPY) -m fem_sim mesh $(LIVER) --scene $(P_SCENE) --out $(PATIENT)/mesh.h5 --no-picture
	$(TPY) -m surrogate truth-scene $(P_MODEL) $(LIVER) --scene $(P_SCENE) \
	    --sims $$(($(K) + $(HELD) > 0 ? $(K) + $(HELD) : 1)) \
	    $(if $(FRAME),--frame $(FRAME)) --out $(PATIENT)/scene.toml $(if $(SITE),--near $(SITE)) \
	    --placement $(PATIENT)/placement.npz --mesh $(PATIENT)/mesh.h5
	$(MPIRUN) $(SPY) -m fem_sim generate $(PATIENT)/scene.toml --out $(PATIENT)/data
	$(SPY) -m fem_sim linear $(PATIENT)/scene.toml --out $(PATIENT)/data $(if $(P_GRASP),--green \
	    --order 1,--synthetic $(SYNTHETIC) --order $(ORDER) $(if $(filter 1,$(GREEN)),--green))
	$(TPY) -m surrogate adapt $(P_MODEL) $(PATIENT)/data --liver $(LIVER) --run $(PATIENT)/run \
	    --sims $(K) --synthetic $(SYNTHETIC) $(if $(FRAME),--frame $(FRAME)) \
	    --placement $(PATIENT)/placement.npz $(if $(REST),--rest $(REST)) $(ADAPT)

# A new liver in seconds (surrogate/over_green.py): MODEL, a population model of what each
# liver's linear response misses (config population_green), placed on the liver file LIVER;
# the liver meshed as the population's livers were and fixed where the placement puts the
# template's fixed region (truth-scene), its small-strain Green's function from one
# factorisation (fem_sim linear --green --green-near: a grasp's patch, a force's node), and
# predict-liver --base on its own mesh with the force
# AT = "X Y Z FX FY FZ" (mm, N; the liver file's frame), or a grasp GRASP = "X Y Z DX DY DZ"
# (the 10 mm patch nearest to X Y Z moved by DX DY DZ mm: the field and the tool's force; a
# model of grasps adds its network's rest and stiffens the force, a model of forces gives
# the small-strain base alone: docs/surgical_loads.md). No MODEL: the shipped model of forces
# models/scene4_forces, or of grasps models/scene4_grasp (cards there). No FE simulation, no
# training. One trainer process drives one solver process (python -m fem_sim serve) through
# these commands (surrogate/make_liver.py), each side working while the other does.
AT ?=
GRASP ?=
LIVER_DIR ?= runs/liver/$(basename $(notdir $(LIVER)))
SHIPPED_GRASP := models/scene4_grasp
SHIPPED_FORCES := models/scene4_forces
LIVER_MODEL = $(or $(MODEL),$(if $(GRASP),$(SHIPPED_GRASP),$(SHIPPED_FORCES)))
liver-args:
	@$(SYS_PY) scripts/make_args.py liver LIVER="$(LIVER)" MODEL="$(LIVER_MODEL)" AT="$(AT)" \
	    GRASP="$(GRASP)" PSCENE="$(PSCENE)" FRAME="$(FRAME)"
liver: liver-args setup
	$(TPY) -m surrogate.make_liver $(LIVER_MODEL) $(LIVER) --scene $(PSCENE) --dir $(LIVER_DIR) \
	    --solver $(SPY) $(if $(FRAME),--frame $(FRAME)) \
	    $(if $(GRASP),--grasp "$(GRASP)",--force "$(AT)")

# The manipulator on a liver make liver prepared (the same LIVER, LIVER_DIR and MODEL): a
# solver process keeps the liver factorised and solves the unit responses of each new patch
# the tool grasps (make liver's are its load's only; the rest solved in the background while
# the window is open). No MODEL: the shipped model of grasps; MODEL=models/scene4_forces:
# forces (handles, push / pull). VIEW: more viewer flags, e.g. --offscreen --out DIR.
VIEW ?=
manipulate: setup
	@test -f $(LIVER_DIR)/data/linear.h5 || { echo "make manipulate: no" \
	    "$(LIVER_DIR)/data/linear.h5: run make liver LIVER=$(LIVER) GRASP=... first" >&2; exit 2; }
	$(TPY) -m surrogate.viewer $(or $(MODEL),$(SHIPPED_GRASP) --grasp) --place $(LIVER) \
	    --base $(LIVER_DIR)/data --solver $(SPY) $(if $(FRAME),--frame $(FRAME)) $(VIEW)

# Scene 4 on real livers (long, resumable): the designs cross-validated by liver, the livers
# never seen against FE (and make liver timed on each) -> docs/scene4_real.md (then make
# table4 T4=--report-only puts its rows into docs/table4.md); a new patient against K with
# its model -> docs/patient.md.
scene4-real: setup
	$(TPY) bench/scene4_real.py --np $(NP)

bench-patient: setup
	$(TPY) bench/patient.py --np $(NP)

# A patient's model of grasps on the 15 validation livers (resumable, about 45 minutes):
# make patient LOAD=grasp at a site of each, its corrections against K -> docs/patient_grasps.md
bench-patient-grasps: setup
	$(TPY) bench/patient_grasps.py

# Surgical loads (resumable): grasps pulled 5-40 mm and 0.4-4 N on a patch, FE against the
# small-strain base over each validation liver's Green's function -> docs/surgical_loads.md;
# then the rows of the model of grasps (GRASP_MODEL: the shipped one, or make
# bench-grasp-rest's) and of the model of forces (FORCE_MODEL) beside the base's, placed on
# each liver in the trainer's environment
GRASP_MODEL ?= $(SHIPPED_GRASP)
FORCE_MODEL ?= $(SHIPPED_FORCES)
bench-surgical: setup-solver setup-trainer
	$(SPY) bench/surgical_loads.py
	$(TPY) bench/surgical_loads.py --report-only --model $(GRASP_MODEL) --force-model $(FORCE_MODEL)

# make liver GRASP=... with the shipped model timed from each validation liver's file, one
# after the other on a quiet machine -> docs/surgical_loads.md
bench-ready: setup
	$(TPY) bench/surgical_loads.py --ready

bench-grasp-rest: setup
	$(TPY) bench/grasp_rest.py --sims 290

evaluate: setup-trainer
	$(TPY) -m surrogate evaluate $(RUN) $(DATA) $(if $(LIVER),--liver $(LIVER)) \
	    --out $(RUN)/evaluation.json

# FEM price list (resumable: re-run to continue): docs/tradeoff_fem.{md,png}; one run at a
# time on FEM_THREADS threads (the machine's two cores by default)
FEM_THREADS ?= 2
tradeoff-fem: setup-solver
	$(SPY) bench/tradeoff_fem.py --threads $(FEM_THREADS)

# Surrogate price list + error budget (resumable): docs/tradeoff_surrogate.md, docs/*.png
tradeoff-surrogate: setup
	$(SPY) bench/budget_fem.py
	$(TPY) bench/tradeoff_surrogate.py --np $(NP)
	$(TPY) bench/budget_fem.py --errors

# Real-time designs side by side (long, resumable): scene 1 at the paper's size (400
# simulations, make table4's scene-1 dataset; generate skips what is done), each design trained
# on the same folds, latency at ~15k nodes -> docs/realtime.md. RT_DATA=DIR uses another
# scene-1 dataset; RT="--evaluate-folds 0" holds out every fold (about 45 min of training on
# two cores, against about 25 min for the first 2 of 5).
RT_DATA ?= bench/results/table4/scene1_base/data
RT      ?= --evaluate-folds 2
bench-realtime: setup
	$(MPIRUN) $(SPY) -m fem_sim generate data_spec/scenes/scene1_base.toml --out $(RT_DATA)
	$(TPY) bench/bench_realtime.py --data $(RT_DATA) $(RT)

# The paper's Table 4, scene by scene (long, resumable; about an hour per scene on 2 cores,
# an hour and a half for scene 4):
# generate, train, time -> docs/table4.md. T4="--scenes 1 2 --budget-minutes 90" passes options.
T4 ?=
table4: setup  # latency on both cores: the trainer keeps its BLAS threads (the ranks get one)
	env -u OMP_NUM_THREADS -u OPENBLAS_NUM_THREADS \
	    $(TPY) bench/table4.py --np $(NP) --solver-python $(SPY) $(T4)

population: setup-solver
	$(SPY) -m fem_sim population $(SCENE) --out $(OUT)

docs: setup-solver
	$(SPY) scripts/render_phantoms.py docs/phantoms.png

viewer: setup-trainer
	$(TPY) -m surrogate.viewer $(RUN)

# The README's animation and comparison, from the run `make demo` trains (runs/demo).
DEMO_RUN := runs/demo/train
docs-manipulator: setup-trainer
	@test -f $(DEMO_RUN)/model/model.json || { echo "run make demo first"; exit 2; }
	rm -rf runs/docs-manipulator
	$(TPY) -m surrogate.viewer $(DEMO_RUN) --offscreen --out runs/docs-manipulator --size 480 380
	cp runs/docs-manipulator/manipulator.gif docs/manipulator.gif
	$(TPY) -m surrogate.viewer $(DEMO_RUN) --compare --data runs/demo/data --offscreen \
	    --out runs/docs-manipulator
	cp runs/docs-manipulator/compare_sim*.png docs/compare.png

# Manipulator frame rate: make demo's liver (1.1k nodes) and a 15k-node real liver (needs
# ../shared/data/livers/sofa_liver.vtk; its small dataset and model are built first, resumable).
VIEWER_DATA := bench/results/viewer/data
VIEWER_RUN  := bench/results/viewer/train
bench-viewer: setup
	@test -f $(DEMO_RUN)/model/model.json || { echo "run make demo first"; exit 2; }
	$(MPIRUN) $(SPY) -m fem_sim generate bench/viewer_sofa.toml --out $(VIEWER_DATA)
	test -f $(VIEWER_RUN)/model/model.json || \
	    $(TPY) -m surrogate train --data $(VIEWER_DATA) --run $(VIEWER_RUN) epochs=5
	test -f $(VIEWER_RUN)_basis/model/model.json || \
	    $(TPY) -m surrogate train --data $(VIEWER_DATA) --run $(VIEWER_RUN)_basis \
	    --config basis epochs=30 folds=2
	$(TPY) bench/bench_viewer.py --run $(DEMO_RUN) --run $(VIEWER_RUN) --run $(VIEWER_RUN)_basis \
	    --md docs/viewer.md
	$(SPY) -m fem_sim summary $(VIEWER_DATA) --png docs/summary_sofa.png

lint: setup-trainer
	$(TRAIN_VENV)/bin/ruff check .

clean:
	rm -rf $(SOLVER_VENV) $(TRAIN_VENV) runs .pytest_cache .ruff_cache *.egg-info
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
