# Two commands do all set-up on a fresh machine: `make demo` and `make test`.
PY ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
# The CPU build of torch is pinned so CI never pulls a multi-GB CUDA build.
# For a GPU install see docs/INSTALL.md.
TORCH_PIN ?= torch==2.13.0

.PHONY: interval-table pair-table docs docs-quick docs-environment docs-reports docs-accuracy docs-learning foreign-lab-table leaderboard-realistic leaderboard-hard leaderboard-drive leaderboard-drive-v1 tune-drive leaderboard-drive-v2 tune-drive-v2 leaderboard-drive-v3 tune-drive-v3 drive-v3-policy tune-hard hard-policy hard-policy-dagger drive-policy docs-drive demo test test-slow test-all bench leaderboard policy policy-100hz accuracy-table perf clean detection-table protocol-study

$(STAMP): pyproject.toml
	test -d $(VENV) || $(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q $(TORCH_PIN)
	$(BIN)/pip install -q -e '.[test,ray,video,data,hull]'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/addedinertia demo --out out/demo

test: $(STAMP)
	$(BIN)/python -m pytest -n 2 -q

test-slow: $(STAMP)
	$(BIN)/python -m pytest -q -m slow

test-all: $(STAMP)
	$(BIN)/python -m pytest -q -m ''

# Controller benchmark (docs/LEADERBOARD.md, docs/CONTROLLERS.md): every controller on the
# held-out test split of standard-v0, then the ranking with figures. `oracle` and `zero`
# are the reference rows (truth-based tracking: the floor; 0 A: no control).
BENCH_SUITE ?= standard-v0
BENCH_CONTROLLERS ?= oracle zero pd feedforward-pd pid lqr ilc mpc
BENCH_SEEDS ?=
BENCH_JOBS ?= 2
LEADERBOARD_DOC ?= docs/LEADERBOARD.md
LEADERBOARD_HTML ?= out/bench/leaderboard-$(BENCH_SUITE).html
# Learned policies (docs/LEARNING.md), run as onnx:PATH on the same suite, split and seeds.
LEARNED_POLICIES ?= agents/policies/reverse_stroke.onnx agents/policies/reverse_stroke_100hz.onnx
BENCH_ROWS = $(foreach c,$(BENCH_CONTROLLERS),out/bench/$(BENCH_SUITE)-$(c).jsonl) \
	$(foreach p,$(LEARNED_POLICIES),out/bench/$(BENCH_SUITE)-onnx-$(basename $(notdir $(p))).jsonl)

bench: $(STAMP)
	$(BIN)/addedinertia bench run --suite smoke --controller feedforward-pd --out out/bench/smoke-feedforward-pd.jsonl

leaderboard: $(STAMP)
	for c in $(BENCH_CONTROLLERS); do \
	  $(BIN)/addedinertia bench run --suite $(BENCH_SUITE) --split test --controller $$c --jobs $(BENCH_JOBS) --allow-failures \
	    $(if $(BENCH_SEEDS),--seeds $(BENCH_SEEDS)) --out out/bench/$(BENCH_SUITE)-$$c.jsonl || exit 1; \
	done
	for p in $(LEARNED_POLICIES); do \
	  $(BIN)/addedinertia bench run --suite $(BENCH_SUITE) --split test --controller onnx:$$p --jobs $(BENCH_JOBS) --allow-failures \
	    $(if $(BENCH_SEEDS),--seeds $(BENCH_SEEDS)) --out out/bench/$(BENCH_SUITE)-onnx-$$(basename $$p .onnx).jsonl || exit 1; \
	done
	$(BIN)/addedinertia bench leaderboard $(BENCH_ROWS) --format md --out $(LEADERBOARD_DOC) \
	  --title "Leaderboard: $(BENCH_SUITE), held-out test split"
	$(BIN)/addedinertia bench leaderboard $(BENCH_ROWS) --format html --out $(LEADERBOARD_HTML) \
	  --title "Leaderboard: $(BENCH_SUITE), held-out test split"

# Retrain and re-export the shipped policy (docs/LEARNING.md; about 20 min on 2 shared cores).
policy: $(STAMP)
	$(BIN)/addedinertia train --algo ppo --config configs/algos/ppo_residual.yaml --residual --timesteps 40000 --seed 1 --out out/train/ppo-residual
	$(BIN)/addedinertia export out/train/ppo-residual --onnx agents/policies/reverse_stroke.onnx

# The 100 Hz policy for the two-rate bench (residual on lqr, base at the policy rate; docs/LEARNING.md, docs/BENCH.md).
policy-100hz: $(STAMP)
	$(BIN)/addedinertia train --algo ppo --config configs/algos/ppo_residual_100hz.yaml --timesteps 50000 --seed 1 --out out/train/ppo-residual-100hz
	$(BIN)/addedinertia export out/train/ppo-residual-100hz --onnx agents/policies/reverse_stroke_100hz.onnx

# The learned residual controller for hard-v0 (docs/LEARNING.md, issue 13): three seeds of random
# search on the paired score, 6 CPU-minutes each, on hard-v0's training split; then the curves,
# the choice of seed on held-aside training scenarios and the export (about 15 min on 2 idle cores).
HARD_SEEDS ?= 0 1 2
comma := ,
empty :=
space := $(empty) $(empty)
hard-policy: $(STAMP)
	for s in $(HARD_SEEDS); do \
	  nice -n 10 $(BIN)/python -m addedinertia_env.learning.ars_residual --seed $$s --generations 200 \
	    --cpu-minutes 6 --out out/train/ars-hard-s$$s || exit 1; \
	done
	$(BIN)/python -m addedinertia_env.reports.ars_curves --runs $(foreach s,$(HARD_SEEDS),out/train/ars-hard-s$(s)) \
	  --validate 24 --onnx agents/policies/hard_residual.onnx --figure docs/figures/learning_hard_ars.png \
	  --summary docs/figures/learning_hard_ars.json

# The oracle distilled by DAgger (docs/LEARNING.md, issue 13): three seeds of a correction on pid
# that acts in the hold (the shipped configuration) and, for comparison, three of a correction
# on pd that acts on the reverse stroke; each 6 iterations of 128 training scenarios (about 1.2
# CPU-minutes a run); then the curves, the choice of seed on held-aside training scenarios and the
# export (about 7 CPU-minutes in all).
DAGGER_ARGS ?= --iterations 6 --scenarios 128 --hidden 32 --fit-steps 3000 --beta-decay 0.5 --cpu-minutes 4
hard-policy-dagger: $(STAMP)
	for s in $(HARD_SEEDS); do \
	  nice -n 10 $(BIN)/python -m addedinertia_env.learning.dagger --base pid --gate hold --seed $$s $(DAGGER_ARGS) \
	    --out out/train/dagger-hold-s$$s || exit 1; \
	  nice -n 10 $(BIN)/python -m addedinertia_env.learning.dagger --base pd --gate reverse --seed $$s $(DAGGER_ARGS) \
	    --out out/train/dagger-reverse-s$$s || exit 1; \
	done
	nice -n 10 $(BIN)/python -m addedinertia_env.reports.dagger_curves \
	  --group "pid + correction in the hold=$(subst $(space),$(comma),$(foreach s,$(HARD_SEEDS),out/train/dagger-hold-s$(s)))" \
	  --group "pd + correction on the reverse stroke=$(subst $(space),$(comma),$(foreach s,$(HARD_SEEDS),out/train/dagger-reverse-s$(s)))" \
	  --validate 48 --onnx agents/policies/hard_dagger.onnx --figure docs/figures/learning_hard_dagger.png \
	  --summary docs/figures/learning_hard_dagger.json

# The learned drive controller (docs/LEARNING.md, issue 28 item 6): random search on the drive suite's
# ranked score (mean min(|e|, 10 %), capped-mean-v3 on this geared suite), a gated linear correction on lqr
# at 100 Hz on the batched engine (the base chosen on the tuning split as the residual runs it, at 100 Hz:
# lqr 0.096 %, cogging-ff 0.108, feedforward-pd 0.201, pid 0.904 %), one seed, the command kept inside 90 % of
# i_max (--action-limit), stopped by --cpu-minutes 12 (about 48 CPU-s a generation on the shared 2-core EPYC:
# 16 generations, 13.5 CPU-minutes with the validation); then its curves and the export (ONNX + card).
DRIVE_SUITE ?= drive-v1
DRIVE_ARS_ARGS ?= --base lqr --seed 0 --scenarios 32 --generations 200 --cpu-minutes 12 --validate 256 --action-limit 0.9
# the run tried first and not shipped (a residual on pid, whose gains chatter at the residual's 100 Hz), for the curves
DRIVE_ARS_PID_ARGS ?= --base pid --seed 0 --scenarios 32 --generations 200 --cpu-minutes 14 --validate 256 --action-limit 0.9
DRIVE_POLICIES ?= agents/policies/drive_ars.onnx
drive-policy: $(STAMP)
	nice -n 10 $(BIN)/python -m addedinertia_env.learning.score_ars --suite $(DRIVE_SUITE) $(DRIVE_ARS_ARGS) \
	  --out out/train/score-ars-$(DRIVE_SUITE) --onnx agents/policies/drive_ars.onnx
	nice -n 10 $(BIN)/python -m addedinertia_env.learning.score_ars --suite $(DRIVE_SUITE) $(DRIVE_ARS_PID_ARGS) \
	  --out out/train/score-ars-$(DRIVE_SUITE)-pid
	$(BIN)/python -m addedinertia_env.reports.score_ars_curves --runs out/train/score-ars-$(DRIVE_SUITE) \
	  out/train/score-ars-$(DRIVE_SUITE)-pid --figure docs/figures/learning_drive_ars.png --summary docs/figures/learning_drive_ars.json

# docs/ENVIRONMENT.md's reward alignment on drive-v0, and a drive-v0 comparison run of the same trainer
# (docs/LEARNING.md, "Also tried earlier") with its curves beside the shipped drive-v1 run's (make drive-policy).
# The comparison figure goes to out/figures: docs/figures/learning_drive_ars.png is drive-policy's (lqr and pid runs).
docs-drive: $(STAMP)
	$(BIN)/python -m addedinertia_env.reports.reward_alignment --suite drive-v0 --scenarios 32 --json out/reward_alignment_drive-v0.json
	nice -n 10 $(BIN)/python -m addedinertia_env.learning.score_ars --suite drive-v0 --seed 0 --cpu-minutes 4 --generations 200 \
	  --validate 64 --out out/train/score-ars-drive-v0-s0
	mkdir -p out/figures
	$(BIN)/python -m addedinertia_env.reports.score_ars_curves --runs out/train/score-ars-drive-v1 out/train/score-ars-drive-v0-s0 \
	  --figure out/figures/learning_drive_ars_v1_v0.png --summary out/figures/learning_drive_ars_v1_v0.json

accuracy-table: $(STAMP)
	$(BIN)/python -m addedinertia_env.reports.accuracy_table --hulls 24 --out docs/ACCURACY.md

clean:
	rm -rf out build *.egg-info .pytest_cache

# docs/DISCOVERY.md: two hidden effects at once, every pair of the vocabulary (issue 27)
pair-table: $(STAMP)
	$(BIN)/python -m addedinertia_env.reports.pair_table --seeds 3 --none-seeds 4 --out docs/DISCOVERY.md
	$(BIN)/python -m addedinertia_env.reports.pair_table --quirks --first-seed 2 --seeds 1 --none-seeds 2 --out docs/DISCOVERY.md --jsonl out/pair-table-quirks.jsonl

# docs/DISCOVERY.md: detection and false-alarm rates of `discover` (about 1 min per dataset of 4 runs on 2 cores)
detection-table: $(STAMP)
	$(BIN)/python -m addedinertia_env.reports.detection_table --seeds 10 --out docs/DISCOVERY.md

# docs/PERFORMANCE.md: single MuJoCo env vs batched physics, 1..16384 envs, one run.
perf: $(STAMP)
	$(BIN)/addedinertia perf --max-envs 16384 --vector-envs 1024 --vector-steps 400 --vector-warmup 1000 --vector-seconds 20 --vector-repeats 3 --out docs/PERFORMANCE.md --json

# docs/LEADERBOARD_realistic.md: the same controllers on realistic-v0 (realistic sensors everywhere).
leaderboard-realistic:
	$(MAKE) leaderboard BENCH_SUITE=realistic-v0 LEADERBOARD_DOC=docs/LEADERBOARD_realistic.md

# docs/LEADERBOARD_hard.md: hard-v0, the suite where control matters (configs/suites/hard-v0.yaml).
leaderboard-hard:
	$(MAKE) leaderboard BENCH_SUITE=hard-v0 LEADERBOARD_DOC=docs/LEADERBOARD_hard.md \
	  LEADERBOARD_HTML=docs/leaderboard_hard.html \
	  LEARNED_POLICIES="agents/policies/reverse_stroke.onnx agents/policies/hard_residual.onnx agents/policies/hard_dagger.onnx"

# docs/LEADERBOARD_memory.md: memory-v1 (water that remembers), ranked on the memory-corrected estimate
# (configs/suites/memory-v1.yaml `ranked:`); about 10-15 s per episode on the shared 2 cores.
leaderboard-memory:
	$(MAKE) leaderboard BENCH_SUITE=memory-v1 LEADERBOARD_DOC=docs/LEADERBOARD_memory.md \
	  BENCH_CONTROLLERS="oracle zero pd lqr" LEARNED_POLICIES= BENCH_JOBS=1

# docs/LEADERBOARD_drive-v1.md: drive-v1, the geared, cogging drive on a 24 V supply (configs/suites/drive-v1.yaml,
# docs/DRIVE.md); `make tune-drive` first. The drive board of issue 28 is drive-v3's (`make leaderboard-drive`).
leaderboard-drive-v1:
	$(MAKE) leaderboard BENCH_SUITE=drive-v1 LEADERBOARD_DOC=docs/LEADERBOARD_drive-v1.md \
	  LEADERBOARD_HTML=out/bench/leaderboard-drive-v1.html LEARNED_POLICIES="$(DRIVE_POLICIES)" \
	  BENCH_CONTROLLERS="$(DRIVE_CONTROLLERS)"

# Every classical entry on drive-v1's tuning split with one budget: 8 candidates (the defaults and 7
# random draws over its KNOBS) x the first 8 tuning scenarios = 64 episodes, ranked score
# (configs/controllers/tuned-drive-v1.yaml; docs/DRIVE.md). `pd` too: its loop gains, no observer.
DRIVE_CONTROLLERS ?= oracle zero pd pid lqr feedforward-pd drive-aware backlash-inversion pid-antiwindup cogging-ff
DRIVE_TUNED ?= feedforward-pd pd pid lqr drive-aware backlash-inversion pid-antiwindup
tune-drive: $(STAMP)
	for c in $(DRIVE_TUNED); do \
	  $(BIN)/addedinertia bench tune --suite drive-v1 --controller $$c --candidates 8 --scenarios 8 --seed 0 \
	    --jobs $(BENCH_JOBS) --no-progress || exit 1; \
	done

# docs/LEADERBOARD_drive-v2.md: drive-v2, drive-v1's drive on a 12-24 V supply behind a 1-16 ms link
# (configs/suites/drive-v2.yaml, docs/DRIVE.md "drive-v2"); `make tune-drive-v2` first (same budget as
# tune-drive: 8 candidates x 8 tuning scenarios, configs/controllers/tuned-drive-v2.yaml).
DRIVE_V2_CONTROLLERS ?= oracle zero pd pid lqr feedforward-pd drive-aware backlash-inversion pid-antiwindup cogging-ff
tune-drive-v2: $(STAMP)
	for c in $(DRIVE_TUNED); do \
	  $(BIN)/addedinertia bench tune --suite drive-v2 --controller $$c --candidates 8 --scenarios 8 --seed 0 \
	    --jobs $(BENCH_JOBS) --no-progress || exit 1; \
	done
leaderboard-drive-v2:
	$(MAKE) leaderboard BENCH_SUITE=drive-v2 LEADERBOARD_DOC=docs/LEADERBOARD_drive-v2.md \
	  LEADERBOARD_HTML=out/bench/leaderboard-drive-v2.html LEARNED_POLICIES= \
	  BENCH_CONTROLLERS="$(DRIVE_V2_CONTROLLERS)"

# drive-v3: drive-v2's physics with the link's round trip stated to the controllers (+-1 ms), a fresh
# 64-scenario test split (configs/suites/drive-v3.yaml, docs/DRIVE.md "drive-v3 and smith-pd"). Its
# tuning split is drive-v2's, so tuned-drive-v3.yaml carries drive-v2's gains for the older entries;
# `make tune-drive-v3` tunes only the entries new on drive-v3, with the same budget.
DRIVE_V3_TUNED ?= smith-pd
DRIVE_V3_CONTROLLERS ?= oracle zero pd pid lqr feedforward-pd drive-aware backlash-inversion pid-antiwindup cogging-ff supply-aware smith-pd
tune-drive-v3: $(STAMP)
	for c in $(DRIVE_V3_TUNED); do \
	  $(BIN)/addedinertia bench tune --suite drive-v3 --controller $$c --candidates 8 --scenarios 8 --seed 0 \
	    --jobs $(BENCH_JOBS) --no-progress || exit 1; \
	done
# docs/LEADERBOARD_drive.md, the drive board (issue 28): drive-v3's 64 test scenarios, every classical entry, the
# references and the learned residual on smith-pd (`make drive-v3-policy`); about 30 min with --jobs 2 on 2 cores.
DRIVE_V3_POLICIES ?= agents/policies/drive_v3_ars.onnx
leaderboard-drive:
	$(MAKE) leaderboard BENCH_SUITE=drive-v3 LEADERBOARD_DOC=docs/LEADERBOARD_drive.md \
	  LEADERBOARD_HTML=out/bench/leaderboard-drive-v3.html LEARNED_POLICIES="$(DRIVE_V3_POLICIES)" \
	  BENCH_CONTROLLERS="$(DRIVE_V3_CONTROLLERS)" BENCH_JOBS=2
leaderboard-drive-v3: leaderboard-drive

# The drive-v3 policy (docs/LEARNING.md "drive-v3"): a gated linear residual on smith-pd trained by ARS on the
# ranked score, six runs (seeds 0-3; 16 scenarios x 4 directions, or 32 x 8; one with scale 0.1), 6.3 CPU-minutes
# of search each, then validated on 64 unseen training-split scenarios; the shipped one is the best validated
# (seed 3, 16 x 4), exported to agents/policies/drive_v3_ars.onnx. The shipped run was made on a 16-core host,
# six runs at once; here they run one after another (about 45 min on 2 cores).
DRIVE_V3_ARS = --suite drive-v3 --base smith-pd --generations 200 --cpu-minutes 6.3 --validate 64 --action-limit 0.9
DRIVE_V3_RUNS = s0-16:--seed_0_--scenarios_16_--directions_4_--top_2 s1-16:--seed_1_--scenarios_16_--directions_4_--top_2 \
  s3-16:--seed_3_--scenarios_16_--directions_4_--top_2_--onnx_agents/policies/drive_v3_ars.onnx s2-16-scale01:--seed_2_--scenarios_16_--directions_4_--top_2_--scale_0.1 \
  s0-32:--seed_0_--scenarios_32_--directions_8_--top_4 s1-32:--seed_1_--scenarios_32_--directions_8_--top_4
drive-v3-policy: $(STAMP)
	for r in $(DRIVE_V3_RUNS); do \
	  nice -n 10 $(BIN)/python -m addedinertia_env.learning.score_ars $(DRIVE_V3_ARS) $$(echo $${r#*:} | tr _ ' ') \
	    --out out/train/ars-drive-v3/$${r%%:*} || exit 1; \
	done
	$(BIN)/python -m addedinertia_env.reports.score_ars_curves --runs out/train/ars-drive-v3/s0-16 out/train/ars-drive-v3/s1-16 out/train/ars-drive-v3/s3-16 out/train/ars-drive-v3/s2-16-scale01 out/train/ars-drive-v3/s0-32 out/train/ars-drive-v3/s1-32 --figure docs/figures/learning_drive_v3_ars.png --summary docs/figures/learning_drive_v3_ars.json

# Re-tune every classical controller on hard-v0's tuning split with one budget
# (configs/controllers/tuned-hard-v0.yaml; about 25 min on 2 shared cores).
TUNE_BUDGET ?= --candidates 8 --scenarios 8 --seed 0
tune-hard: $(STAMP)
	for c in feedforward-pd pid lqr mpc ilc; do \
	  $(BIN)/addedinertia bench tune --suite hard-v0 --controller $$c $(TUNE_BUDGET) --jobs $(BENCH_JOBS) || exit 1; \
	done

# The other lab's development set (docs/DISCOVERY.md, issue 11): discover, whole-record and
# energy on each case, scored against its answers.json. The archive is the developers'
# development set, not part of the project: give its path, make foreign-lab-table FOREIGN_LAB=PATH.
FOREIGN_LAB ?=
FOREIGN_LAB_2 ?=
foreign-lab-table: $(STAMP)
	@test -n "$(FOREIGN_LAB)" || { echo "make foreign-lab-table: give the archive: FOREIGN_LAB=PATH/foreign-lab.tar.xz" >&2; exit 2; }
	$(BIN)/python -m addedinertia_env.reports.foreign_lab --data $(FOREIGN_LAB) --out docs/DISCOVERY.md
	$(if $(FOREIGN_LAB_2),$(BIN)/python -m addedinertia_env.reports.foreign_lab --data $(FOREIGN_LAB_2) --out docs/DISCOVERY.md)

# Interval calibration (docs/INTERVALS.md, issue 26): 26 drawn hulls per water (about an hour of CPU on
# 2 cores), plus the other labs' runs when their archives are given; the rows are kept in out/ (a rerun resumes).
interval-table: $(STAMP)
	$(BIN)/python -m addedinertia_env.reports.interval_calibration run out/intervals/rows.jsonl --sets out/intervals/sets \
		--seeds 13 $(if $(FOREIGN_LAB),--foreign $(FOREIGN_LAB)) $(if $(FOREIGN_LAB_2),--foreign $(FOREIGN_LAB_2))
	$(BIN)/python -m addedinertia_env.reports.interval_calibration render out/intervals/rows.jsonl --out docs/INTERVALS.md

# Every generated reference table and figure in docs/ from one command: `make docs` (hours on
# 2 cores: the leaderboards, the accuracy and detection tables, the learning curves). The
# shipped policies are not retrained (make policy, policy-100hz, hard-policy, hard-policy-dagger
# do that, and rewrite agents/policies/). `make docs-quick` regenerates the tables that take
# minutes. With FOREIGN_LAB=PATH the tables made from the developers' foreign-lab set are
# regenerated too (docs/DISCOVERY.md's, docs/ENERGY_METHOD.md's section).
docs: docs-quick docs-reports docs-accuracy detection-table pair-table perf leaderboard leaderboard-realistic leaderboard-hard docs-learning leaderboard-drive-v1 drive-policy docs-drive drive-v3-policy leaderboard-drive
	$(if $(FOREIGN_LAB),$(MAKE) foreign-lab-table FOREIGN_LAB=$(FOREIGN_LAB) FOREIGN_LAB_2=$(FOREIGN_LAB_2))

docs-quick: docs-environment
	$(BIN)/python -m addedinertia_env.reports.hydrodynamics
	mkdir -p out && $(BIN)/addedinertia decay --textbook --plot docs/figures/textbook_decay.png --json > out/textbook_decay.json

# docs/ENVIRONMENT.md: the reference returns (zero, random, feedforward-pd; env seeds 0-4).
docs-environment: $(STAMP)
	$(BIN)/python -m addedinertia_env.reports.environment_returns --episodes 5 --out docs/ENVIRONMENT.md

docs-reports: $(STAMP)
	$(BIN)/python -m addedinertia_env.reports.energy_budget --seeds 4 $(if $(FOREIGN_LAB),--data $(FOREIGN_LAB))
	$(BIN)/python -m addedinertia_env.reports.bem_prior --seeds 4
	$(BIN)/python -m addedinertia_env.reports.radiation_memory --seeds 3 --out docs/RADIATION_MEMORY.md
	$(MAKE) protocol-study
	$(BIN)/python -m addedinertia_env.reports.oracle_ablation --scenarios 48 --out docs/figures/oracle_ablation_hard.json

# docs/RADIATION_MEMORY.md, "The protocol's part": hold, twist, window and forced runs in water that
# remembers, before and after the memory correction (~10 CPU min; resumes from out/protocol_study/rows.jsonl).
protocol-study: $(STAMP)
	$(BIN)/python -m addedinertia_env.reports.protocol_study --seeds 2 --free-seeds 8 --out docs/RADIATION_MEMORY.md

docs-accuracy: accuracy-table
	$(BIN)/python -m addedinertia_env.reports.accuracy_table --hulls 8 --out docs/ACCURACY_bearing_coulomb.md --effect bearing_coulomb
	$(BIN)/python -m addedinertia_env.reports.accuracy_table --hulls 8 --out docs/ACCURACY_fluid_memory.md --effect fluid_memory

# docs/LEARNING.md's curve sections (one per algorithm; finished runs in out/curves are reused).
docs-learning: $(STAMP)
	$(BIN)/python -m addedinertia_env.reports.learning_curves --algo ppo --seeds 0 1 2 --timesteps 60000 --eval-every 10000 --eval-episodes 8 --runs out/curves
	$(BIN)/python -m addedinertia_env.reports.learning_curves --algo sac --seeds 0 1 2 --timesteps 20000 --eval-every 4000 --eval-episodes 8 --runs out/curves
	$(BIN)/python -m addedinertia_env.reports.learning_curves --algo recurrent-ppo --seeds 0 1 2 --timesteps 40000 --eval-every 8000 --eval-episodes 8 --runs out/curves
