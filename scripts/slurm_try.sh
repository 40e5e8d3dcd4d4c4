#!/usr/bin/env bash
# The SLURM path for real on a single-node cluster (scripts/slurm_single_node.sh, started here as root):
#   1. a small sweep (2 MM-2FSK cells x 2 captures) into a fresh store: every cell computed;
#   2. the same sweep again: every cell from the store;
#   3. a sweep of two new cells where one job is cancelled (scancel) while it waits: the sweep names the cell and
#      its cause, merges the finished one and exits 1;
#   4. the same command again: the finished cell from the store, the cancelled one computed; exit 0;
#   5. a job that fails with its own error (MM-2FSK asked for all frequencies) beside a cell from the store;
#   6. jobs killed for memory (50 MB per CPU, 100 MB per job: a job from the store peaks at 160-310 MB; slurmd
#      polls every 2 s and kills the step, jobacct_gather/linux OverMemoryKill);
#   7. a job killed at its time limit (BP_max without skips under a 1-minute limit, one BLAS thread, no warning
#      signal) beside a cell that finishes;
#   8. the same under a 2-minute limit with SLURM's warning signal 60 s before it (submitit's --signal, as the
#      presets have it with 120 s): the job stops itself and exits cleanly, reported timed out from its result.
# 5-8 each: the missing cells named with their cause, the finished ones merged, exit 1. With --accounting the
# cluster runs slurmdbd (MariaDB) and the causes of 3-7 must come from sacct (`[sacct: <state>, exit code <code>]`);
# without, from scontrol or the job's log.
# Usage: sudo bash scripts/slurm_try.sh [--accounting] [OUT]   (default OUT: outputs/slurm-try; any disk will do,
# as BENCH_SLURM_LOCAL_PATHS=1 is set: this cluster has one node). Steps 1-4 took 5.8 min at load 13 on 2 cores
# (generating the two captures included; they are cached afterwards).
set -euo pipefail
cd "$(dirname "$0")/.."
mode=""
[ "${1:-}" = --accounting ] && { mode=--accounting; shift; }
out="$(realpath -m "${1:-outputs/slurm-try}")"
python="${PYTHON:-.venv/bin/python}"   # PYTHON=... to use another environment
bash scripts/slurm_single_node.sh start $mode >/dev/null
rm -rf "$out"; mkdir -p "$out"
export BENCH_SLURM_LOCAL_PATHS=1
source="job log|scontrol"
[ -n "$mode" ] && source="sacct"
sweep() {   # sweep <name> <experiment> <override>...
    local name="$1" experiment="$2"
    shift 2
    "$python" -m bench -m "experiment=$experiment" \
        'dataset.captures=[01_plate/30,03_sphere/30]' 'dataset.generate.objects=[01_plate,03_sphere]' \
        hydra/launcher=slurm_cpu \
        "store.dir=$out/store" "hydra.sweep.dir=$out/$name" "$@"
}
freqs() { echo "hydra.sweeper.params.freq='$1'"; }
counts() {  # counts <sweep root>: "<computed> computed, <cached> cached"
    "$python" -c "import pandas as pd, sys; r = pd.read_csv(sys.argv[1] + '/results.csv'); \
print(f'{int((~r.cached).sum())} computed, {int(r.cached.sum())} cached')" "$1"
}
check() { [ "$2" = "$3" ] || { echo "FAILED: $1: got '$2', expected '$3'" >&2; exit 1; }; echo "ok: $1: $2"; }
failing() {   # failing <step> <sweep name> <experiment> <override>...: a sweep that must exit 1; prints its errors
    local step="$1" name="$2" code started
    shift 2
    started=$SECONDS
    set +e
    sweep "$name" "$@" > "$out/$name.log" 2>&1
    code=$?
    set -e
    echo "$step: $((SECONDS - started)) s; the sweep printed:"
    grep '^error:' "$out/$name.log" | sed 's/^/    /'
    check "$step exits" "$code" "1"
}
cause() {   # cause <sweep name> <cell> <cause regex>: the cell's error line, its cause read from $source
    grep -cE "^error: $2: job [0-9]+ $3.*\[($source)" "$out/$1.log" || true
}

sweep run1 table2 "$(freqs d8,d10)" > "$out/run1.log" 2>&1
check "1. first sweep" "$(counts "$out/run1")" "4 computed, 0 cached"
sweep run2 table2 "$(freqs d8,d10)" > "$out/run2.log" 2>&1
check "2. re-run from the store" "$(counts "$out/run2")" "0 computed, 4 cached"

set +e
sweep run3 table2 "$(freqs d4,d2)" > "$out/run3.log" 2>&1 &
sweep_pid=$!
for _ in $(seq 120); do   # cancel the second cell's job as soon as SLURM lists it
    job="$(squeue -h -n bench-mm2fsk_d2_photogrammetry -o %i | head -1)"
    [ -n "$job" ] && { scancel "$job"; break; }
    sleep 0.5
done
wait "$sweep_pid"; code=$?
set -e
check "3. sweep with a cancelled job exits" "$code" "1"
check "3. the cancelled cell is named with its cause" \
    "$(cause run3 mm2fsk_d2_photogrammetry cancelled)" "1"
check "3. the finished cell is merged" "$(counts "$out/run3")" "2 computed, 0 cached"
sweep run4 table2 "$(freqs d4,d2)" > "$out/run4.log" 2>&1
check "4. the next run resumes" "$(counts "$out/run4")" "2 computed, 2 cached"

failing "5. a job failing with its own error" run5 table2 "$(freqs d8,full)"
check "5. the failed cell is named with the job's error" \
    "$(cause run5 mm2fsk_full_photogrammetry 'failed: mm2fsk needs a 2-frequency configuration')" "1"
check "5. the finished cell is merged" "$(counts "$out/run5")" "0 computed, 2 cached"

failing "6. jobs killed for memory" run6 table2 "$(freqs d8,d10)" hydra.launcher.mem_gb=null hydra.launcher.mem_per_cpu=50M
check "6. both cells are named out of memory" \
    "$(($(cause run6 mm2fsk_d8_photogrammetry 'out of memory') + $(cause run6 mm2fsk_d10_photogrammetry \
    'out of memory')))" "2"
check "6. nothing finished, nothing merged" "$(grep -c 'no cell finished: nothing to merge' "$out/run6.log")" "1"

export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1   # the BP_max jobs below run to their limits: one core only
slow=("hydra.sweeper.params.cell='mm2fsk_d8,bp_full'" +roi=none)
failing "7. a job killed at its time limit" run7 table3 "${slow[@]}" hydra.launcher.timeout_min=1 \
    hydra.launcher.signal_delay_s=0
check "7. the slow cell is named timed out" "$(cause run7 bp_full 'timed out \(time limit 1 min')" "1"
check "7. the finished cell is merged" "$(counts "$out/run7")" "2 computed, 0 cached"

source="job result"   # stopped by submitit at SLURM's warning, the job exits cleanly: sacct says COMPLETED
failing "8. a job stopped at its time-limit warning" run8 table3 "${slow[@]}" hydra.launcher.timeout_min=2 \
    hydra.launcher.signal_delay_s=60
check "8. the slow cell is named timed out" "$(cause run8 bp_full "timed out \(time limit 2 min; stopped at SLURM's warning")" "1"
check "8. the finished cell is merged" "$(counts "$out/run8")" "0 computed, 2 cached"
echo "SLURM path ok (${mode:-no accounting}); logs and sweep roots in $out"
