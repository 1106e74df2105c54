# Quick start: `make run` (main job on the built-in gearbox) and `make test` (lint + the fast
# tests); `make check` runs everything (what CI runs). All create .venv and install gearsym with pinned dependencies on first use: every package
# of the tree at the version in requirements.lock (`make lock` re-resolves it from the pins in
# pyproject.toml).
PYTHON ?= python3.11
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

PIP    := pip==26.3

.PHONY: run test check check-installed lint format bench fuzz mutate lock clean sketches results

$(STAMP): pyproject.toml requirements.lock
	@command -v $(PYTHON) >/dev/null || { echo "make: $(PYTHON) not found (need Python 3.11+; set PYTHON=...)"; exit 2; }
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet '$(PIP)'
	$(BIN)/pip install --quiet -r requirements.lock
	$(BIN)/pip install --quiet --no-deps -e .
	@touch $(STAMP)

# Re-resolve the whole dependency tree from pyproject.toml into requirements.lock.
lock:
	rm -rf .lock-venv
	$(PYTHON) -m venv .lock-venv
	.lock-venv/bin/pip install --quiet '$(PIP)'
	.lock-venv/bin/pip install --quiet -e '.[dev]'
	.lock-venv/bin/pip freeze --exclude-editable > requirements.lock
	rm -rf .lock-venv

run: $(STAMP)
	$(BIN)/gearsym run
	$(BIN)/gearsym estimate --filter ekf --out out/ekf
	$(BIN)/gearsym export-fmu --model shift_2_3 --out out/fmu/gearsym_shift_2_3.fmu
	$(BIN)/gearsym export-a2l --out out/a2l/gearsym.a2l
	@echo "EKF (4.3) on the 2-3 shift: out/ekf/ekf.png (estimates against the truth, ±3σ, phases shaded), ekf_efficiency.png, ekf.csv (docs/ekf.md)"
	@echo "FMU (FMI 2.0 Model Exchange + Co-Simulation, sources): out/fmu/gearsym_shift_2_3.fmu; A2L for INCA/CANape: out/a2l/gearsym.a2l (docs/fmu.md, docs/a2l.md)"
	@echo "Parameter sweeps (Sobol indices on Dask, slower, not run here): $(BIN)/gearsym sweep --param mu_05=0.108:0.132 --param m_veh=1620:1980 --out out/sweep  (results: out/sweep/indices.csv, samples.parquet, sobol_*.png; docs/sweeps.md)"

# The documentation's result tables, written by the evaluation commands (never typed): the EKF
# of the 2-3 upshift over 200 vehicles of the default fleet on evaluation seeds 10000-10199
# (the tuning used seeds 100000-100099): the thesis' filter (about 10 min on one core), and on
# two cores (about 10-15 min each) mu as a scale on the calibration's map (the 2-3, the 3-4 and
# the 1-2), the fleet's tolerances as states, the same read through tooth-wheel speed sensors,
# and the 3-4 with the interval's mean inputs.
RESULTS := docs/results
results: $(STAMP)
	rm -rf build/results/fleet_ekf_2_3
	$(BIN)/gearsym estimate --filter ekf --fleet --runs 200 --seed 10000 --scheduler local --out build/results/fleet_ekf_2_3
	mkdir -p $(RESULTS)
	cp build/results/fleet_ekf_2_3/fleet.json $(RESULTS)/fleet_ekf_2_3.json
	cp build/results/fleet_ekf_2_3/fleet.md $(RESULTS)/fleet_ekf_2_3.md
	cp build/results/fleet_ekf_2_3/fleet.png $(RESULTS)/fleet_ekf_2_3.png
	rm -rf build/results/fleet_ekf_2_3_map_scale
	$(BIN)/gearsym estimate --filter ekf --fleet --input-hold mean --mu-model map_scale --params m_veh,mu_38,mu_05,zeta,k_ss,d_ss,input_torque_gain,inertia_factor,valve_offset,valve_gain --runs 200 --seed 10000 --scheduler local --out build/results/fleet_ekf_2_3_map_scale
	cp build/results/fleet_ekf_2_3_map_scale/fleet.json $(RESULTS)/fleet_ekf_2_3_map_scale.json
	cp build/results/fleet_ekf_2_3_map_scale/fleet.md $(RESULTS)/fleet_ekf_2_3_map_scale.md
	cp build/results/fleet_ekf_2_3_map_scale/fleet.png $(RESULTS)/fleet_ekf_2_3_map_scale.png
	rm -rf build/results/fleet_ekf_3_4_map_scale build/results/fleet_ekf_1_2_map_scale
	$(BIN)/gearsym estimate --filter ekf --fleet --scenario gearsym/data/scenario_3_4.toml --input-hold mean --mu-model map_scale --params m_veh,mu_81,mu_27,zeta,k_ss,d_ss,input_torque_gain,inertia_factor,valve_offset,valve_gain --runs 200 --seed 10000 --scheduler local --out build/results/fleet_ekf_3_4_map_scale
	$(BIN)/gearsym estimate --filter ekf --fleet --scenario gearsym/data/scenario_1_2.toml --input-hold mean --mu-model map_scale --params m_veh,mu_05,mu_81,zeta,k_ss,d_ss,input_torque_gain,inertia_factor,valve_offset,valve_gain --runs 200 --seed 10000 --scheduler local --out build/results/fleet_ekf_1_2_map_scale
	for run in fleet_ekf_3_4_map_scale fleet_ekf_1_2_map_scale; do \
	  cp build/results/$$run/fleet.json $(RESULTS)/$$run.json; \
	  cp build/results/$$run/fleet.md $(RESULTS)/$$run.md; \
	  cp build/results/$$run/fleet.png $(RESULTS)/$$run.png; \
	done
	rm -rf build/results/fleet_ekf_2_3_augmented
	$(BIN)/gearsym estimate --filter ekf --fleet --params m_veh,mu_38,mu_05,zeta,k_ss,input_torque_gain,inertia_factor,valve_offset,valve_gain --runs 200 --seed 10000 --scheduler local --out build/results/fleet_ekf_2_3_augmented
	cp build/results/fleet_ekf_2_3_augmented/fleet.json $(RESULTS)/fleet_ekf_2_3_augmented.json
	cp build/results/fleet_ekf_2_3_augmented/fleet.md $(RESULTS)/fleet_ekf_2_3_augmented.md
	cp build/results/fleet_ekf_2_3_augmented/fleet.png $(RESULTS)/fleet_ekf_2_3_augmented.png
	rm -rf build/results/fleet_ekf_2_3_tooth_wheels
	$(BIN)/gearsym estimate --filter ekf --fleet gearsym/data/fleet_tooth_wheels.toml --params m_veh,mu_38,mu_05,zeta,k_ss,input_torque_gain,inertia_factor,valve_offset,valve_gain --runs 200 --seed 10000 --scheduler local --out build/results/fleet_ekf_2_3_tooth_wheels
	cp build/results/fleet_ekf_2_3_tooth_wheels/fleet.json $(RESULTS)/fleet_ekf_2_3_tooth_wheels.json
	cp build/results/fleet_ekf_2_3_tooth_wheels/fleet.md $(RESULTS)/fleet_ekf_2_3_tooth_wheels.md
	cp build/results/fleet_ekf_2_3_tooth_wheels/fleet.png $(RESULTS)/fleet_ekf_2_3_tooth_wheels.png
	rm -rf build/results/fleet_ekf_3_4_input_mean
	$(BIN)/gearsym estimate --filter ekf --fleet --scenario gearsym/data/scenario_3_4.toml --input-hold mean --params m_veh,mu_81,mu_27,zeta,k_ss,input_torque_gain,inertia_factor,valve_offset,valve_gain --runs 200 --seed 10000 --scheduler local --out build/results/fleet_ekf_3_4_input_mean
	cp build/results/fleet_ekf_3_4_input_mean/fleet.json $(RESULTS)/fleet_ekf_3_4_input_mean.json
	cp build/results/fleet_ekf_3_4_input_mean/fleet.md $(RESULTS)/fleet_ekf_3_4_input_mean.md
	cp build/results/fleet_ekf_3_4_input_mean/fleet.png $(RESULTS)/fleet_ekf_3_4_input_mean.png
	rm -rf build/results/ekf_2_3 build/results/euio_2_3
	$(BIN)/gearsym estimate --filter ekf --runs 50 --seed 0 --out build/results/ekf_2_3
	cp build/results/ekf_2_3/ekf.json $(RESULTS)/montecarlo_ekf_2_3.json
	cp build/results/ekf_2_3/monte_carlo.md $(RESULTS)/montecarlo_ekf_2_3.md
	$(BIN)/gearsym estimate --filter euio --runs 50 --seed 0 --out build/results/euio_2_3
	cp build/results/euio_2_3/euio.json $(RESULTS)/montecarlo_euio_2_3.json
	cp build/results/euio_2_3/monte_carlo.md $(RESULTS)/montecarlo_euio_2_3.md
# The same filters with the truth's modes, at 1 ms, with initial estimates drawn from the prior
# (docs/ekf.md, docs/euio.md; about 5-15 s each).
	rm -rf build/results/montecarlo_*
	$(BIN)/gearsym estimate --filter ekf --runs 50 --seed 0 --modes reference --out build/results/montecarlo_ekf_2_3_reference_modes
	$(BIN)/gearsym estimate --filter ekf --runs 10 --seed 0 --sample-time 0.001 --out build/results/montecarlo_ekf_2_3_1ms
	$(BIN)/gearsym estimate --filter ekf --runs 50 --seed 0 --initial-from-prior --out build/results/montecarlo_ekf_2_3_prior_draws
	$(BIN)/gearsym estimate --filter ekf --runs 50 --seed 0 --initial-from-prior --modes reference --out build/results/montecarlo_ekf_2_3_prior_draws_reference_modes
	$(BIN)/gearsym estimate --filter euio --runs 50 --seed 0 --modes reference --out build/results/montecarlo_euio_2_3_reference_modes
	$(BIN)/gearsym estimate --filter euio --runs 50 --seed 0 --initial-from-prior --out build/results/montecarlo_euio_2_3_prior_draws
	$(BIN)/gearsym estimate --filter euio --runs 50 --seed 0 --initial-from-prior --modes reference --out build/results/montecarlo_euio_2_3_prior_draws_reference_modes
	for run in build/results/montecarlo_*; do \
	  cp $$run/*.json $(RESULTS)/$$(basename $$run).json; \
	  cp $$run/monte_carlo.md $(RESULTS)/$$(basename $$run).md; \
	done
	rm -rf build/results/uio_2_3_10ms build/results/uio_2_3_1ms build/results/uio_2_3_noise
	$(BIN)/gearsym estimate --filter uio --out build/results/uio_2_3_10ms
	$(BIN)/gearsym estimate --filter uio --sample-time 0.001 --out build/results/uio_2_3_1ms
	$(BIN)/gearsym estimate --filter uio --noise 0.001 --out build/results/uio_2_3_noise
	for run in 10ms 1ms noise; do \
	  cp build/results/uio_2_3_$$run/uio.json $(RESULTS)/uio_2_3_$$run.json; \
	  cp build/results/uio_2_3_$$run/uio.md $(RESULTS)/uio_2_3_$$run.md; \
	done
# The analyses' tables (about 3 min more): the Fisher information of the 2-3 on the hybrid model
# in both views (docs/hybrid.md), the open-loop study restarted per phase and carried over
# (docs/sensitivities.md), the freewheel shifts against the reference (docs/hybrid.md), and the
# MISRA findings of generated/c (docs/misra.md; cppcheck), and the emitted TCU task on the
# emulated Cortex-M4F (docs/control.md: instructions per call, code size; QEMU).
	rm -rf build/results/fim_hybrid_2_3 build/results/fim_hybrid_2_3_known_initial_state
	$(BIN)/gearsym fim --out build/results/fim_hybrid_2_3
	$(BIN)/gearsym fim --known-initial-state --out build/results/fim_hybrid_2_3_known_initial_state
	rm -rf build/results/fim_open_loop_2_3 build/results/fim_open_loop_2_3_carry_over
	$(BIN)/gearsym fim --open-loop --with-wheel-acceleration --out build/results/fim_open_loop_2_3
	$(BIN)/gearsym fim --open-loop --with-wheel-acceleration --carry-over --out build/results/fim_open_loop_2_3_carry_over
	for run in hybrid_2_3 hybrid_2_3_known_initial_state open_loop_2_3 open_loop_2_3_carry_over; do \
	  cp build/results/fim_$$run/fim.json $(RESULTS)/fim_$$run.json; \
	  cp build/results/fim_$$run/fim.md $(RESULTS)/fim_$$run.md; \
	done
	rm -rf build/results/one_way_simpson
	$(BIN)/python -m gearsym.validation.sim.one_way_comparison --out build/results/one_way_simpson
	cp build/results/one_way_simpson/one_way.json $(RESULTS)/one_way_simpson.json
	cp build/results/one_way_simpson/one_way.md $(RESULTS)/one_way_simpson.md
	rm -rf build/results/misra
	$(BIN)/python -m gearsym.validation.checks.misra --out build/results/misra
	cp build/results/misra/misra.json $(RESULTS)/misra.json
	cp build/results/misra/misra.md $(RESULTS)/misra.md
	rm -rf build/results/tcu_task_2_3
	$(BIN)/python -m gearsym.validation.checks.qemu_control --shift 2-3 --out build/results/tcu_task_2_3
	cp build/results/tcu_task_2_3/tcu_task_2_3.json $(RESULTS)/tcu_task_2_3.json
	cp build/results/tcu_task_2_3/tcu_task_2_3.md $(RESULTS)/tcu_task_2_3.md
	rm -rf build/results/tcu_task_3_2
	$(BIN)/python -m gearsym.validation.checks.qemu_control --shift 3-2 --out build/results/tcu_task_3_2
	cp build/results/tcu_task_3_2/tcu_task_3_2.json $(RESULTS)/tcu_task_3_2.json
	cp build/results/tcu_task_3_2/tcu_task_3_2.md $(RESULTS)/tcu_task_3_2.md
	rm -rf build/results/tcu_task_3_4
	$(BIN)/python -m gearsym.validation.checks.qemu_control --shift 3-4 --out build/results/tcu_task_3_4
	cp build/results/tcu_task_3_4/tcu_task_3_4.json $(RESULTS)/tcu_task_3_4.json
	cp build/results/tcu_task_3_4/tcu_task_3_4.md $(RESULTS)/tcu_task_3_4.md
	rm -rf build/results/tcu_tasks
	$(BIN)/python -m gearsym.validation.checks.qemu_tasks --out build/results/tcu_tasks
	cp build/results/tcu_tasks/tcu_tasks.json $(RESULTS)/tcu_tasks.json
	cp build/results/tcu_tasks/tcu_tasks.md $(RESULTS)/tcu_tasks.md
# A whole WLTC class 3b drive with the EKF over it, the calibration's own vehicle and a fleet
# vehicle (docs/drive.md; about 1-2 min each: the fast drive and the EKF over its log), then 100
# vehicles of the fleet (about 80-90 min on two cores).
	rm -rf build/results/drive_wltc3b
	$(BIN)/gearsym drive --cycle wltc3b --out build/results/drive_wltc3b
	cp build/results/drive_wltc3b/drive.json $(RESULTS)/drive_wltc3b.json
	cp build/results/drive_wltc3b/drive.md $(RESULTS)/drive_wltc3b.md
	cp build/results/drive_wltc3b/drive.png $(RESULTS)/drive_wltc3b.png
	cp build/results/drive_wltc3b/estimates.png $(RESULTS)/drive_wltc3b_estimates.png
	rm -rf build/results/drive_wltc3b_fleet_10000
	$(BIN)/gearsym drive --cycle wltc3b --fleet --seed 10000 --out build/results/drive_wltc3b_fleet_10000
	cp build/results/drive_wltc3b_fleet_10000/drive.json $(RESULTS)/drive_wltc3b_fleet_10000.json
	cp build/results/drive_wltc3b_fleet_10000/drive.md $(RESULTS)/drive_wltc3b_fleet_10000.md
	cp build/results/drive_wltc3b_fleet_10000/estimates.png $(RESULTS)/drive_wltc3b_fleet_10000_estimates.png
	rm -rf build/results/drive_wltc3b_fleet
	$(BIN)/gearsym drive --cycle wltc3b --fleet --runs 100 --seed 10000 --scheduler local --out build/results/drive_wltc3b_fleet
	cp build/results/drive_wltc3b_fleet/fleet.json $(RESULTS)/drive_wltc3b_fleet.json
	cp build/results/drive_wltc3b_fleet/fleet.md $(RESULTS)/drive_wltc3b_fleet.md
	cp build/results/drive_wltc3b_fleet/fleet.png $(RESULTS)/drive_wltc3b_fleet.png
# The adaptive-control study (docs/control.md): 100 vehicles of the default fleet x 20 2-3
# upshifts x 4 strategies (the issue's size), 20 vehicles with cold oil (every element's mu
# +25 %), 30 vehicles of 3-4 and 20 vehicles x 10 power-on 3-2 downshifts (about 120, 25, 40
# and 10 min on two cores).
	rm -rf build/results/control_2_3 build/results/control_3_4 build/results/control_2_3_cold build/results/control_3_2
	$(BIN)/gearsym control --fleet --strategies fixed,rule,estimator,oracle --shifts 20 --runs 100 --seed 10000 --scheduler local --out build/results/control_2_3
	$(BIN)/gearsym control --fleet --fix mu_scale=1.25 --strategies fixed,rule,estimator,oracle --shifts 20 --runs 20 --seed 10000 --scheduler local --out build/results/control_2_3_cold
	$(BIN)/gearsym control --scenario gearsym/data/scenario_3_4.toml --fleet --strategies fixed,rule,estimator,oracle --shifts 20 --runs 30 --seed 10000 --scheduler local --out build/results/control_3_4
	$(BIN)/gearsym control --scenario gearsym/data/scenario_3_2_power_on.toml --fleet --strategies fixed,rule,estimator,oracle --shifts 10 --runs 20 --seed 10000 --scheduler local --out build/results/control_3_2
	for run in control_2_3 control_2_3_cold control_3_4 control_3_2; do \
	  cp build/results/$$run/control.json $(RESULTS)/$$run.json; \
	  cp build/results/$$run/control.md $(RESULTS)/$$run.md; \
	  cp build/results/$$run/sequence.png $(RESULTS)/$${run}_sequence.png; \
	  cp build/results/$$run/shift.png $(RESULTS)/$${run}_shift.png; \
	done

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

# Tests run on both cores (pytest-xdist; PYTEST_WORKERS=1 for one). The fast tier leaves out
# the tests marked slow (Monte-Carlo runs, QEMU, every-shift builds, the larger fuzz budget,
# compile-and-compare of whole trees); `make check` runs them all, then the installed-wheel run.
PYTEST_WORKERS ?= 2
PYTEST := $(BIN)/python -m pytest -q -n $(PYTEST_WORKERS) --dist loadfile

test: lint
	$(PYTEST) -m "not slow"

# Everything: the fast tier (`make test`), then the tests marked slow, the installed wheel and
# the documentation site (its tutorial notebook executed).
check: test
	$(PYTEST) -m slow
	bash .ci/check-installed
	$(MAKE) docs

check-installed:
	bash .ci/check-installed

# The nightly hostile-input run: the property suite with a larger budget (fixed seed).
fuzz: $(STAMP)
	GEARSYM_FUZZ_EXAMPLES=$${GEARSYM_FUZZ_EXAMPLES:-2000} $(BIN)/python -m pytest -q tests/test_fuzz_cli.py

# The periodic mutation run (not part of `make check`): mutmut over the dynamics, the EKF and
# the C printer with a targeted fast test subset, staged in build/mutation/ (.ci/mutate.py says
# why); writes the score and the survivors to docs/results/mutation.md. About 30 min on 2 cores.
mutate: $(STAMP)
	$(BIN)/python .ci/mutate.py

format: $(STAMP)
	$(BIN)/ruff format .
	$(BIN)/ruff check --fix .

# The set-kind sketches (docs/set-kinds.md): one stick diagram per planetary set kind, drawn by gearsym
# from the minimal descriptions in docs/set_kinds/ (deterministic SVG bytes).
SET_KINDS := simple double_pinion ravigneaux ravigneaux_two_rings stepped_planet
sketches: $(STAMP)
	@for kind in $(SET_KINDS); do \
		$(BIN)/gearsym draw docs/set_kinds/$$kind.toml --what stick --out docs/set_kinds/$$kind.svg || exit 1; \
	done

# The documentation site (mkdocs.yml, docs/) into site/, warnings as errors; the tutorial
# notebook is executed during the build. Its tools are pinned in requirements-docs.lock and
# installed into .venv on top of requirements.lock, whose pins they leave as they are. The API
# reference reads the package as installed (symbolic/ as gearsym/symbolic, ...): build/docs-src.
DOCS_STAMP := $(VENV)/.docs-installed

$(DOCS_STAMP): $(STAMP) requirements-docs.lock
	$(BIN)/pip install --quiet -r requirements-docs.lock -c requirements.lock
	@touch $(DOCS_STAMP)

.PHONY: docs
docs: $(DOCS_STAMP)
	rm -rf build/docs-src && mkdir -p build
	$(BIN)/pip install --quiet --no-deps --no-compile --target build/docs-src . \
		2>build/docs-src.log || { cat build/docs-src.log; exit 1; }
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --site-dir site

bench: $(STAMP)
	$(BIN)/python benchmarks/run_all.py

clean:
	rm -rf $(VENV) .lock-venv build site *.egg-info .pytest_cache .ruff_cache
