# opend-mj: every command a user or CI needs. `make quickstart` then `make test`.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
CABINETS ?= cabinets
WORKERS  ?= $(shell nproc)
export MUJOCO_GL ?= egl
export PYTHONUNBUFFERED := 1

.PHONY: quickstart evaluate results eval-real robustness robustness-hands robustness-depth robustness-real expert-check train-bc install install-mjx install-warp test-warp bench-warp install-lerobot system-deps assets test fuzz bench bench-quick bench-assets bench-assets-real bench-hands bench-task bench-env bench-demos bench-agents clean

## Set up from nothing, build the default (procedural) dataset and run the main job: the planner with
## the oracle handle solver on the test split (Allegro hand), scored into the paper's tables.
quickstart: install assets evaluate

QUICKSTART_OUT ?= results/quickstart
evaluate: install
	mkdir -p $(QUICKSTART_OUT)
	$(BIN)/opend run --hand allegro --solver oracle --split test --workers $(WORKERS) \
		--cabinets $(CABINETS) --out $(QUICKSTART_OUT)/oracle_allegro_test.jsonl
	$(BIN)/opend score $(QUICKSTART_OUT)/oracle_allegro_test.jsonl \
		--csv $(QUICKSTART_OUT)/scores.csv --plot $(QUICKSTART_OUT)/scores.png

## Every generated-split file under results/ from scratch (the README's tables come from these; about
## 50 min on 2 cores): oracle, CLIPort and Faster R-CNN with all four hands on the procedural test split,
## the oracle (Shadow) and both learned solvers (all hands) at light x 0.7, all three with reworded
## instructions (the hand-written corpus of tests/data), and the 1/120 s physics step; then `opend report`.
## The rest of results/: results/real/ (make eval-real) and results/bc/<hand>_shipped_test.jsonl (the
## shipped behaviour-cloning policies, docs/demonstrations.md). tests/evaluation/test_results_dir.py
## fails on any other file there.
## Every hand, in its order, as `opend hands` lists them (a hand is its folder under hands/).
HANDS = $(foreach h,$(or $(shell $(BIN)/opend hands --names),$(error `$(BIN)/opend hands` listed no hands)),--hand $(h))
RUN   := $(BIN)/opend run --split test --workers $(WORKERS) --cabinets $(CABINETS)
LEARNED_RESULTS := cliport_test cliport_test_light07 cliport_test_corpus \
	fasterrcnn_test fasterrcnn_test_light07 fasterrcnn_test_corpus
results: install
	rm -f results/oracle_test.jsonl results/oracle_test_dt120.jsonl results/oracle_test_light07.jsonl \
		results/oracle_test_corpus.jsonl $(foreach f,$(LEARNED_RESULTS),results/$(f).jsonl)
	$(RUN) $(HANDS) --solver oracle --out results/oracle_test.jsonl
	$(RUN) $(HANDS) --solver oracle --instruction-file tests/data/instruction_corpus.csv \
		--out results/oracle_test_corpus.jsonl
	$(RUN) $(HANDS) --solver oracle --physics-timestep 1/120 --out results/oracle_test_dt120.jsonl
	$(RUN) --hand shadow --solver oracle --light-scale 0.7 --out results/oracle_test_light07.jsonl
	for s in cliport fasterrcnn; do \
		$(RUN) $(HANDS) --solver $$s --out results/$${s}_test.jsonl && \
		$(RUN) $(HANDS) --solver $$s --light-scale 0.7 --out results/$${s}_test_light07.jsonl && \
		$(RUN) $(HANDS) --solver $$s --instruction-file tests/data/instruction_corpus.csv \
			--out results/$${s}_test_corpus.jsonl || exit 1; done
	for f in oracle_test oracle_test_dt120 oracle_test_corpus $(LEARNED_RESULTS); do \
		$(BIN)/opend score results/$$f.jsonl --plot results/$$f.png > /dev/null; done
	$(BIN)/opend report

## Real cabinets: compile your PartNet-Mobility folder (SOURCE=..., optionally IDS=a,b,c), run the
## oracle planner with all four hands on every target, and score it. Episode records stay under build/
## (git-ignored): PartNet-Mobility is non-commercial, nothing built from it belongs in the repository;
## only the per-hand aggregates (results/real/<solver>_<split><tag>.json) are written for `opend report`.
## SPLIT=test runs the validation part only; SOLVER=cliport or SOLVER=fasterrcnn runs a learned solver;
## RUN_ARGS='--light-scale 0.7' (or '--paraphrase 2', '--seed 1') with TAG=_light07 adds a condition.
SOURCE ?= ../shared/opend-train
SOLVER ?= oracle
REAL_CABINETS ?= build/$(notdir $(abspath $(SOURCE)))
REAL_OUT ?= build/real-results
SPLIT ?= all
RUN_ARGS ?=
TAG ?=
eval-real: install
	$(BIN)/opend build-assets --source $(SOURCE) --out $(REAL_CABINETS) --workers $(WORKERS) $(if $(IDS),--ids $(IDS))
	mkdir -p $(REAL_OUT)
	$(BIN)/opend run $(HANDS) --solver $(SOLVER) --split $(SPLIT) \
		--workers $(WORKERS) --cabinets $(REAL_CABINETS) $(RUN_ARGS) --out $(REAL_OUT)/$(SOLVER)_real$(TAG).jsonl
	$(BIN)/opend score $(REAL_OUT)/$(SOLVER)_real$(TAG).jsonl --csv $(REAL_OUT)/$(SOLVER)_scores$(TAG).csv \
		--plot $(REAL_OUT)/$(SOLVER)_scores$(TAG).png --summary results/real/$(SOLVER)_$(SPLIT)$(TAG).json \
		--manifest $(REAL_CABINETS)/manifest.json

## Robustness (docs/robustness.md): nominal and every perturbation axis at both levels, for the solvers
## and agents in ROBUST_SOLVERS (the BC policy too) with the hands in ROBUST_HANDS. `robustness`: the
## generated test split (records and table under results/robustness/); `robustness-real`: your compiled
## PartNet-Mobility folder as for eval-real (records under build/, only the table's counts in
## results/real/robustness_<split><tag>.json).
ROBUST_SOLVERS ?= --solver oracle --solver fasterrcnn --solver cliport --policy bc
ROBUST_HANDS ?= --hand allegro --hand franka
robustness: install
	$(BIN)/opend robustness $(ROBUST_SOLVERS) $(ROBUST_HANDS) --split test --workers $(WORKERS) $(RUN_ARGS) \
		--records results/robustness --out results/robustness/generated
## End to end with Faster R-CNN, all four hands, every axis at both levels (the bands' check per hand).
robustness-hands: install
	$(BIN)/opend robustness --solver fasterrcnn $(HANDS) --split test --workers $(WORKERS) \
		--records results/robustness --out results/robustness/hands
## The robust baseline under depth noise (docs/robustness.md): Faster R-CNN and the detector trained on
## the depth sensor's images (fasterrcnn-sensor), all four hands, nominal and depth_noise at both levels.
robustness-depth: install
	$(BIN)/opend robustness --solver fasterrcnn --solver fasterrcnn-sensor $(HANDS) --split test --axis depth_noise \
		--workers $(WORKERS) --records results/robustness --out results/robustness/depth_noise
robustness-real: install
	$(BIN)/opend build-assets --source $(SOURCE) --out $(REAL_CABINETS) --workers $(WORKERS) $(if $(IDS),--ids $(IDS))
	$(BIN)/opend robustness $(ROBUST_SOLVERS) $(ROBUST_HANDS) --split $(SPLIT) --cabinets $(REAL_CABINETS) \
		--workers $(WORKERS) $(RUN_ARGS) --records $(REAL_OUT)/robustness --out $(REAL_OUT)/robustness/real$(TAG)
	mkdir -p results/real
	cp $(REAL_OUT)/robustness/real$(TAG).json results/real/robustness_$(SPLIT)$(TAG).json
	cp $(REAL_OUT)/robustness/real$(TAG).png results/real/robustness_$(SPLIT)$(TAG).png

## The planner as an interactive expert (docs/demonstrations.md): episodes of the generated test split taken
## over mid-way from the planner itself, every hand, at four switch times.
expert-check: install
	$(BIN)/opend expert-check $(HANDS) --switch 2 --switch 4 \
		--switch 6 --switch 8 --workers $(WORKERS) --out results/expert/planner_test.jsonl

## One hand's behaviour-cloning policy (generated cabinets only; deterministic for SEED), resumable:
## the planner's demonstrations, round 0 and DAgger rounds with the planner as expert, each round's
## policy and validation figures kept in checkpoints/bc_rounds/$(HAND)/ (commit them: a later run
## continues from the last round kept, and makes the rollouts again from them where build/ lacks
## them), the final policy (every training cabinet, from the best round) shipped as
## checkpoints/bc_$(HAND).pt, then its record on the generated test split. Prints each stage's wall time.
## HAND=allegro DAGGER=3 (rounds after round 0) SEEDS=2 STEPS=3000 (round 0) ROUND_STEPS=2000 (later
## rounds, warm-started) FINAL_STEPS=6000 REVISIT=1 (each round's failed rollouts rolled out again, at
## other seeds) HOLD=1 (rollouts go on to the policy's stop after the expert's plan opened the part,
## labelled "stay"); kept rounds keep their own; BC_ARGS: more `opend train-policy` options (--grasp-token).
HAND ?= allegro
DAGGER ?= 3
REVISIT ?= 1
HOLD ?= 1
SEEDS ?= 2
STEPS ?= 3000
ROUND_STEPS ?= 2000
FINAL_STEPS ?= 6000
SEED ?= 0
## LONG_DOORS=N: N extra training cabinets of the long_door family (`opend generate --family long_door`,
## built into LONG_DIR), their demonstrations, and their targets rolled out in every DAgger round
## (`--extra-cabinets`); 0: none.
LONG_DOORS ?= 0
LONG_DIR ?= build/cabinets-long
## VARIANT=name: another DAgger run of the hand, on the hand's own demonstrations, kept apart: its
## rounds and final policy in checkpoints/bc_rounds/$(HAND)-name/, its work in build/bc/$(HAND)-name/.
## ENSEMBLE (default ENSEMBLE_<hand>): variants, each made with its VARIANT_<name> settings, whose final
## policies the shipped checkpoint averages with this run's (`opend bundle-policy`; the main run's final
## policy is then kept in checkpoints/bc_rounds/$(HAND)/final.pt): runs trained on other data err
## differently, and their mean errs less.
VARIANT ?=
VARIANT_long = LONG_DOORS=80 REVISIT=1 HOLD=1
ENSEMBLE_skeleton = long
ENSEMBLE ?= $(ENSEMBLE_$(HAND))
RUN = $(HAND)$(if $(VARIANT),-$(VARIANT))
DEMO_DIR ?= build/bc/$(HAND)
BC_DIR ?= build/bc/$(RUN)
KEEP = checkpoints/bc_rounds/$(RUN)
POLICY_OUT = $(if $(VARIANT)$(ENSEMBLE),$(KEEP)/final.pt,checkpoints/bc_$(HAND).pt)
LONG_ARGS = $(if $(filter-out 0,$(LONG_DOORS)),--demos $(DEMO_DIR)/demos_long.hdf5 --extra-cabinets $(LONG_DIR))
## BC_THREADS: torch threads of training (both cores by default; 1 where another job shares them:
## more threads than free cores slow training many times over)
BC_THREADS ?= $(WORKERS)
BC_ARGS ?=
train-bc: install assets
	@t=$$(date +%s); $(BIN)/opend demos --cabinets $(CABINETS) --hand $(HAND) --split train --seeds $(SEEDS) \
		--solver oracle --workers $(WORKERS) --out $(DEMO_DIR)/demos.hdf5 && \
		echo "train-bc: demonstrations $$(( $$(date +%s) - t )) s"
ifneq ($(LONG_DOORS),0)
	@t=$$(date +%s); $(BIN)/opend generate --family long_door --start 2000 --count $(LONG_DOORS) \
		--out $(LONG_DIR)-src && $(BIN)/opend build-assets --source $(LONG_DIR)-src --out $(LONG_DIR) \
		--workers $(WORKERS) --no-progress && $(BIN)/opend demos --cabinets $(LONG_DIR) --hand $(HAND) --split all \
		--seeds $(SEEDS) --solver oracle --workers $(WORKERS) --out $(DEMO_DIR)/demos_long.hdf5 && \
		echo "train-bc: long-door cabinets and their demonstrations $$(( $$(date +%s) - t )) s"
endif
	@t=$$(date +%s); $(BIN)/opend train-policy --demos $(DEMO_DIR)/demos.hdf5 $(LONG_ARGS) --hand $(HAND) --steps $(STEPS) \
		--seed $(SEED) --dagger $(DAGGER) --round-steps $(ROUND_STEPS) --final-steps $(FINAL_STEPS) --revisit $(REVISIT) \
		$(if $(filter 1,$(HOLD)),--hold-after-plan,--no-hold-after-plan) \
		--cabinets $(CABINETS) --dagger-dir $(BC_DIR)/dagger --keep-rounds $(KEEP) \
		--workers $(WORKERS) --threads $(BC_THREADS) $(BC_ARGS) --out $(POLICY_OUT) && \
		echo "train-bc: $(RUN): DAgger rounds and final policy $$(( $$(date +%s) - t )) s"
ifeq ($(VARIANT),)
ifneq ($(ENSEMBLE),)
	@$(foreach v,$(ENSEMBLE),$(MAKE) --no-print-directory train-bc HAND=$(HAND) VARIANT=$(v) $(VARIANT_$(v)) &&) true
	$(BIN)/opend bundle-policy $(POLICY_OUT) $(foreach v,$(ENSEMBLE),checkpoints/bc_rounds/$(HAND)-$(v)/final.pt) \
		--out checkpoints/bc_$(HAND).pt
endif
	@t=$$(date +%s); rm -f results/bc/$(HAND)_shipped_test.jsonl; $(BIN)/opend run --policy bc \
		--policy-arg checkpoint=checkpoints/bc_$(HAND).pt --hand $(HAND) --split test --cabinets $(CABINETS) \
		--workers $(WORKERS) --out results/bc/$(HAND)_shipped_test.jsonl && \
		echo "train-bc: test split $$(( $$(date +%s) - t )) s"
endif

## System libraries for off-screen rendering (EGL through Mesa; no GPU needed).
system-deps:
	@if ldconfig -p | grep -q 'libEGL_mesa.so.0' && ldconfig -p | grep -q 'libOpenGL.so.0'; then \
		echo "system-deps: EGL present"; \
	else \
		SUDO=$$( [ "$$(id -u)" = 0 ] || echo sudo ); \
		$$SUDO apt-get update -qq && $$SUDO apt-get install -y -qq libegl1 libegl-mesa0 libgl1-mesa-dri libopengl0; \
	fi

install: system-deps $(VENV)/.installed

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -e '.[test]'
	touch $@

## Optional: MJX (MuJoCo in JAX) for opend_mj.sim.batched and its tests (~90 MB download, ~385 MB
## installed, so `install` and CI leave it out; see docs/batched-simulation.md).
install-mjx: install
	$(BIN)/pip install -q -e '.[mjx]'

## The optional extra for batched environments on MuJoCo Warp (opend_mj.sim.warp_env, docs/batched-simulation.md):
## mujoco-warp and warp-lang, ~600 MB; runs on the CPU, and on an NVIDIA GPU where Warp finds one.
install-warp: install
	$(BIN)/pip install -q -e '.[warp]'

## The Warp tests (CPU device; they skip without the extra): batched steps against the CPU environment.
## The first run compiles Warp's kernels (about a minute on 2 cores; cached under ~/.cache/warp).
test-warp: install-warp
	$(BIN)/python -m pytest -q tests/sim/test_warp_env.py

## Environment steps per second of the batched Warp environment at N = 1, 16, 256, 4096 (as far as
## BENCH_WARP_SECONDS allows) on the device Warp finds, beside the CPU environment's in the same run.
BENCH_WARP_SECONDS ?= 600
bench-warp: install-warp
	$(BIN)/python tools/bench_warp.py --cabinets $(CABINETS) --budget $(BENCH_WARP_SECONDS)

## LeRobot's library in an environment of its own (it pins torch < 2.11, this project 2.14), for
## tools/demos_to_lerobot.py: about 8 GB with torch's CUDA wheels.
LEROBOT_VENV ?= build/lerobot-venv
install-lerobot:
	test -x $(LEROBOT_VENV)/bin/python || $(PYTHON) -m venv $(LEROBOT_VENV)
	$(LEROBOT_VENV)/bin/pip install -q 'lerobot==0.4.*' h5py

## Compile the default dataset: 346 procedural sources -> cabinets/ + manifest.json.
assets: install
	$(BIN)/opend build-assets --out $(CABINETS) --workers $(WORKERS) --no-progress

## The test suite, slow tests included (CI runs them), in TEST_WORKERS pytest-xdist processes (0: one
## process); --dist loadfile keeps each file's tests in one process (module fixtures are built once),
## and the compiled-cabinet fixtures are shared by the processes (tests/conftest.py). pytest's exit 5,
## "no tests collected", is a failure too.
TEST_WORKERS ?= 2
test: install
	$(BIN)/python -m pytest -q -n $(TEST_WORKERS) --dist loadfile; status=$$?; \
	if [ $$status -eq 5 ]; then echo "no tests were collected"; fi; exit $$status

## The fuzzer, long: FUZZ_CASES mutated sources (procedural, plus the PartNet-Mobility sample when
## ../shared has it) and a third as many mutated results files; prints the outcome table, fails if any
## case ended otherwise than built or refused in one named line (tests/assets/test_fuzz.py runs a short one).
FUZZ_CASES ?= 600
FUZZ_SEED  ?= 0
FUZZ_REAL  ?= ../shared/partnet-sample/45780
fuzz: install
	$(BIN)/python tools/fuzz.py --cases $(FUZZ_CASES) --seed $(FUZZ_SEED) \
		$(if $(wildcard $(FUZZ_REAL)/mobility.urdf),--real $(FUZZ_REAL))

bench: install
	$(BIN)/python tools/bench.py

bench-quick: install
	$(BIN)/python tools/bench.py --quick

bench-assets: install
	$(BIN)/python tools/bench_assets.py --out build/bench-cabinets

## Real cabinets (PartNet-Mobility layout, e.g. SOURCE=../shared/opend-train), one worker: cold and cached
## seconds, hulls, physics checks, collision-vs-visual fidelity -> build/bench-real/summary.md; the compiled
## dataset (with manifest.json) stays in $(REAL_CABINETS), shared with eval-real. EVERY=7 measures every 7th source.
EVERY ?= 1
bench-assets-real: install
	@if [ ! -d "$(SOURCE)" ]; then echo "bench-assets-real: no source folder $(SOURCE) (set SOURCE=...)"; exit 2; fi
	$(BIN)/python tools/bench_assets_real.py --source $(SOURCE) --out build/bench-real \
		--cabinets $(REAL_CABINETS) --every $(EVERY)

bench-hands: install
	$(BIN)/python tools/bench_hands.py

clean:
	rm -rf build $(CABINETS)/*/ $(CABINETS)/manifest.json

bench-task: install
	$(BIN)/python tools/bench_task.py

## Environment steps/s against MuJoCo's own rate, in interleaved chunks, wall and CPU time, load average printed:
## raw mj_step ceiling, state steps/s (the compiled and the Python step) and their ratio, the shared-memory vector env (1 and 2 workers,
## step_in_main), two free-running processes as the reference, RGB-D at 128 and 256 against the renderer
## (also in `make bench`).
bench-env: install
	$(BIN)/python tools/bench_env.py --cabinets $(CABINETS)

## Demonstrations recorded per minute (1 and 2 workers), bytes per demonstration, training samples per
## second and the peak memory of training (CPU, 1 thread); the section is written into BENCHMARKS.md
## (also in `make bench`).
bench-demos: install
	$(BIN)/python tools/bench_demos.py --cabinets $(CABINETS) --write BENCHMARKS.md

## The agent channel (`opend run --policy`: observation out, action back over a pipe) per step beside the
## physics step, and the BC policy's act apart and in-process; the section is written into BENCHMARKS.md
## (also in `make bench`).
bench-agents: install
	$(BIN)/python tools/bench_agent_channel.py --cabinets $(CABINETS) --write BENCHMARKS.md
