# sit2stand: the two commands a newcomer needs are `make demo` and `make test`; both set everything up first.
SHELL := /bin/bash
VENV  := .venv
PY    := $(VENV)/bin/python
# Keep DDS traffic on this machine; tests pick their own ROS_DOMAIN_ID per test.
export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST
export RCUTILS_COLORIZED_OUTPUT ?= 0
SOAK_MIN ?= 2
BATCH_CASES ?= 40

.PHONY: setup demo figures test test-fast lint bench bench-gap bench-gap-human bench-retarget bench-human bench-capture bench-live bench-ik bench-driver bench-estimator results bench-standup bench-batch bench-faults lock clean

setup:            ## create .venv (pinned wheels, ROS 2 Jazzy), build msgs/, install src/ (idempotent)
	@ros_ws/bootstrap.sh

demo: setup       ## the main job on the shipped demonstrations, TALOS then G1 (writes runs/demo/, runs/demo_g1/)
	@$(PY) -m sit2stand.demo --out runs/demo
	@$(PY) -m sit2stand.demo --robot g1 --out runs/demo_g1

figures: setup     ## the docs' pictures: Rerun's own viewer (headless) mid-rise on the demo's stand-ups, TALOS and G1, and on iCub's and Alexander's offline ones (runs `make demo` first if runs/demo is missing; needs Vulkan: Debian's mesa-vulkan-drivers)
	@test -d runs/demo/natural/standup || $(MAKE) demo
	@$(PY) -m sit2stand.cli view runs/demo/natural --screenshot docs/figures/view_talos.png
	@$(PY) -m sit2stand.cli view runs/demo_g1/natural --screenshot docs/figures/view_g1.png
	@rm -rf runs/icub_natural && $(PY) -m sit2stand.cli retarget bags/natural --robot icub --simulate --out runs/icub_natural > /dev/null
	@$(PY) -m sit2stand.cli view runs/icub_natural --screenshot docs/figures/view_icub.png
	@rm -rf runs/alexander_natural && $(PY) -m sit2stand.cli retarget bags/natural --robot alexander --simulate --out runs/alexander_natural > /dev/null
	@$(PY) -m sit2stand.cli view runs/alexander_natural --screenshot docs/figures/view_alexander.png

test: setup lint  ## lint, then the whole test suite: unit tests (2 workers, a file per worker), then the graph and cluster tests alone
	@$(PY) -m pytest -q -n 2 --dist loadfile --durations=8 -m "not graph and not cluster" tests
	@$(PY) -m pytest -q --durations=8 -m "graph or cluster" tests

lint: setup       ## ruff (ruff.toml): zero findings
	@$(VENV)/bin/ruff check

test-fast: setup  ## unit tests only (no node processes)
	@$(PY) -m pytest -q tests -m "not graph and not cluster"

bench: setup      ## speed figures (printed and written to bench/results/bench.json); not a test
	@$(PY) -m sit2stand.bench --out bench/results/bench.json

bench-gap: setup  ## only the model-gap hit rates (10 hidden-effect plants per kind: 14 kinds in the library, 2 outside it), merged into bench.json
	@$(PY) -m sit2stand.bench --only gap --out bench/results/bench.json

bench-gap-human: setup  ## only the human-side model-gap hit rates (20 digital humans per case: a mass hidden on each of 9 segment groups, a scale error, nothing), merged into bench.json
	@$(PY) -m sit2stand.bench --only gap_human --out bench/results/bench.json

bench-retarget: setup  ## only the retargeting figures (IK per frame, latency in the live graphs), merged into bench.json
	@$(PY) -m sit2stand.bench --only retarget --out bench/results/bench.json

bench-human: setup  ## the human COM on the real lab recordings of ../shared/data/real: Newton residuals, merged into bench.json
	@$(PY) -m sit2stand.bench --only human --out bench/results/bench.json

bench-capture: setup  ## the mocap bridge 10 min at 200 Hz against serve-c3d: frames lost, memory growth, latency; merged into bench.json
	@$(PY) -m sit2stand.bench.capture --out bench/results/bench.json

bench-live: setup     ## the live stand-up (serve-c3d -> bridge -> estimator -> retargeter -> robot) 5 times: capture -> markers / COM / joint command p50, p99; bench/results/live.json
	@$(PY) -m sit2stand.bench.live --out bench/results/live.json

bench-ik: setup       ## the per-frame IK against mink and pink (DAQP, ProxQP) on the identical problems of a bags/natural run, in .venv-ik: p50, p99, ratios, agreement; bench/results/ik.json
	@$(PY) -m sit2stand.bench.ik --out bench/results/ik.json

bench-driver: setup   ## the plant's step per on-board controller against a bare mj_step, and the driver node's real-time factor (joint PD, whole-body torque control), merged into bench.json
	@$(PY) -m sit2stand.bench --only driver --out bench/results/bench.json

bench-estimator: setup  ## the streaming human COM estimator per frame (no ROS, and its node in a real-time graph), merged into bench.json
	@$(PY) -m sit2stand.bench --only estimator --out bench/results/bench.json

results: setup       ## rewrite the generated tables of docs/results.md from bench/results/*.json (each with its date, commit, command)
	@$(PY) -m sit2stand.bench.report

bench-standup: setup  ## 30 digital humans (stature, mass, seat, natural/elderly/fast) retargeted and simulated: success, time scale, COM, torque; bench/results/standup/ (BENCH_STANDUP_ARGS="--robot g1": standup_g1/)
	@$(PY) -m sit2stand.bench.standup $(BENCH_STANDUP_ARGS)

bench-batch: setup  ## a stand-up batch (BATCH_CASES G1 digital humans, default 40; CAD) in one process, on Ray with 1 and with 2 workers: throughput and ratios; bench/results/batch.json
	@$(PY) -m sit2stand.bench.batch --cases $(BATCH_CASES) --out bench/results/batch.json

bench-faults: setup  ## fault campaign (corrupt/cut files, NaN/missing/mm markers, bad identification, killed recorder, second graph) + a SOAK_MIN-minute soak (default 2; the full soak: SOAK_MIN=30); bench/results/faults.json
	@$(PY) -m sit2stand.bench.faults --soak-min $(SOAK_MIN) --out bench/results/faults.json

lock:             ## re-pin constraints.txt from the current .venv (after changing requirements.txt)
	@(echo "# Full pinned closure of ros_ws/requirements.txt (pip freeze on Python 3.11, Linux x86_64). Regenerate with: make lock"; \
	  $(PY) -m pip freeze --exclude-editable | sort) > ros_ws/constraints.txt

clean:            ## remove the venv, colcon build folders and generated runs (shipped bags stay)
	rm -rf $(VENV) .venv-ik ros_ws/build ros_ws/log ros_ws/install runs bags/generated bench/results
