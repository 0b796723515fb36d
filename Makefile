# opend-mj: every command a user or CI needs. `make quickstart` then `make test`.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
CABINETS ?= cabinets
WORKERS  ?= $(shell nproc)
export MUJOCO_GL ?= egl
export PYTHONUNBUFFERED := 1

.PHONY: quickstart evaluate results eval-real install system-deps assets test bench bench-quick bench-assets bench-assets-real bench-hands bench-task bench-env clean

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

## Every committed file under results/ from scratch (the README's tables come from these; about
## 30 min on 2 cores): oracle, CLIPort and Faster R-CNN with all four hands on the procedural test split, the
## Shadow hand at light x 0.7 and with reworded instructions, and the 1/120 s physics step.
HANDS := --hand franka --hand allegro --hand shadow --hand skeleton
RUN   := $(BIN)/opend run --split test --workers $(WORKERS) --cabinets $(CABINETS)
results: install
	rm -f results/oracle_test.jsonl results/oracle_test_dt120.jsonl results/oracle_test_light07.jsonl \
		results/cliport_test.jsonl results/cliport_test_light07.jsonl results/cliport_test_paraphrase2.jsonl \
		results/fasterrcnn_test.jsonl
	$(RUN) $(HANDS) --solver oracle --out results/oracle_test.jsonl
	$(RUN) $(HANDS) --solver oracle --physics-timestep 1/120 --out results/oracle_test_dt120.jsonl
	$(RUN) $(HANDS) --solver cliport --out results/cliport_test.jsonl
	$(RUN) $(HANDS) --solver fasterrcnn --out results/fasterrcnn_test.jsonl
	$(RUN) --hand shadow --solver oracle --light-scale 0.7 --out results/oracle_test_light07.jsonl
	$(RUN) --hand shadow --solver cliport --light-scale 0.7 --out results/cliport_test_light07.jsonl
	$(RUN) --hand shadow --solver cliport --paraphrase 2 --out results/cliport_test_paraphrase2.jsonl
	for f in oracle_test oracle_test_dt120 cliport_test fasterrcnn_test; do \
		$(BIN)/opend score results/$$f.jsonl --plot results/$$f.png > /dev/null; done

## Real cabinets: compile your PartNet-Mobility folder (SOURCE=..., optionally IDS=a,b,c), run the
## oracle planner with all four hands on every target, and score it. The build's hash split is the
## train part (tune on it) and the test part (report it as validation). Outputs stay under build/
## (git-ignored): PartNet-Mobility is non-commercial, nothing built from it belongs in the repository.
## SPLIT=test runs the validation part only; SOLVER=cliport or SOLVER=fasterrcnn runs a learned solver.
SOURCE ?= ../shared/opend-train
SOLVER ?= oracle
REAL_CABINETS ?= build/$(notdir $(abspath $(SOURCE)))
REAL_OUT ?= build/real-results
SPLIT ?= all
eval-real: install
	$(BIN)/opend build-assets --source $(SOURCE) --out $(REAL_CABINETS) --workers $(WORKERS) $(if $(IDS),--ids $(IDS))
	mkdir -p $(REAL_OUT)
	$(BIN)/opend run --hand franka --hand allegro --hand shadow --hand skeleton --solver $(SOLVER) --split $(SPLIT) \
		--workers $(WORKERS) --cabinets $(REAL_CABINETS) --out $(REAL_OUT)/$(SOLVER)_real.jsonl
	$(BIN)/opend score $(REAL_OUT)/$(SOLVER)_real.jsonl --csv $(REAL_OUT)/$(SOLVER)_scores.csv \
		--plot $(REAL_OUT)/$(SOLVER)_scores.png

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

## Compile the default dataset: 346 procedural sources -> cabinets/ + manifest.json.
assets: install
	$(BIN)/opend build-assets --out $(CABINETS) --workers $(WORKERS) --no-progress

## The test suite (pytest's exit 5, "no tests collected", is a failure too).
test: install
	$(BIN)/python -m pytest -q; status=$$?; \
	if [ $$status -eq 5 ]; then echo "no tests were collected"; fi; exit $$status

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

## gymnasium environment steps/s: state-only and RGB-D, 1 process and a 2-process vector env (also in `make bench`).
bench-env: install
	$(BIN)/python tools/bench_env.py --cabinets $(CABINETS)
