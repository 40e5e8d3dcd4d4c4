#!/usr/bin/env bash
# The SLURM path for real on a single-node cluster (scripts/slurm_single_node.sh, started here as root):
#   1. a small sweep (2 MM-2FSK cells x 2 captures) into a fresh store: every cell computed;
#   2. the same sweep again: every cell from the store;
#   3. a sweep of two new cells where one job is cancelled (scancel) while it waits: the sweep names the cell and
#      its cause, merges the finished one and exits 1;
#   4. the same command again: the finished cell from the store, the cancelled one computed; exit 0.
# Usage: sudo bash scripts/slurm_try.sh [OUT]   (default OUT: outputs/slurm-try; any disk will do, as
# BENCH_SLURM_LOCAL_PATHS=1 is set: this cluster has one node). Took 5.8 min at load 13 on 2 cores
# (generating the two captures included; they are cached afterwards).
set -euo pipefail
cd "$(dirname "$0")/.."
out="$(realpath -m "${1:-outputs/slurm-try}")"
python="${PYTHON:-.venv/bin/python}"   # PYTHON=... to use another environment
bash scripts/slurm_single_node.sh start >/dev/null
rm -rf "$out"; mkdir -p "$out"
export BENCH_SLURM_LOCAL_PATHS=1
sweep() {   # sweep <name> <freqs>
    "$python" -m bench -m experiment=table2 "hydra.sweeper.params.freq='$2'" \
        'dataset.captures=[01_plate/30,03_sphere/30]' 'dataset.generate.objects=[01_plate,03_sphere]' \
        hydra/launcher=slurm_cpu \
        "store.dir=$out/store" "hydra.sweep.dir=$out/$1"
}
counts() {  # counts <sweep root>: "<computed> computed, <cached> cached"
    "$python" -c "import pandas as pd, sys; r = pd.read_csv(sys.argv[1] + '/results.csv'); \
print(f'{int((~r.cached).sum())} computed, {int(r.cached.sum())} cached')" "$1"
}
check() { [ "$2" = "$3" ] || { echo "FAILED: $1: got '$2', expected '$3'" >&2; exit 1; }; echo "ok: $1: $2"; }

sweep run1 d8,d10 > "$out/run1.log" 2>&1
check "1. first sweep" "$(counts "$out/run1")" "4 computed, 0 cached"
sweep run2 d8,d10 > "$out/run2.log" 2>&1
check "2. re-run from the store" "$(counts "$out/run2")" "0 computed, 4 cached"

set +e
sweep run3 d4,d2 > "$out/run3.log" 2>&1 &
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
    "$(grep -c '^error: mm2fsk_d2_photogrammetry: job [0-9]* cancelled' "$out/run3.log")" "1"
check "3. the finished cell is merged" "$(counts "$out/run3")" "2 computed, 0 cached"
sweep run4 d4,d2 > "$out/run4.log" 2>&1
check "4. the next run resumes" "$(counts "$out/run4")" "2 computed, 2 cached"
echo "SLURM path ok; logs and sweep roots in $out"
