#!/usr/bin/env bash
# Every GPU figure of docs/measurements/gpu.md round 10 on the device machine, in eleven calls of the `run` tool, back to back
# (a call carries at most 64 MiB: the wheels and the data travel in parts). Here, once:
#   [SEQ=CAPTURE] bash bench/perf/device_figures.sh pack [ROOT]   # ROOT: the 30 cm catalogue (default data/synthetic);
#                    # SEQ: a sequence capture (default: bench.perf.stream's bottle sequence, generated if missing)
# then on the device (each line: the `carry` list, then the command):
#   [".wp0"]           bash bench/perf/device_figures.sh part .wp0
#   [".wp1"]           bash bench/perf/device_figures.sh part .wp1
#   [".wp2", ".whl"]   bash bench/perf/device_figures.sh part .wp2
#   [".o3da"]          bash bench/perf/device_figures.sh part .o3da      # Open3D in three parts: .o3d0 (52 MiB) and the
#   [".o3db"]          bash bench/perf/device_figures.sh part .o3db      # working tree (14 MiB) exceed one call's 64 MiB
#   [".o3dc", ".gl"]   bash bench/perf/device_figures.sh part .o3dc
#   [".gpud0"]         bash bench/perf/device_figures.sh part .gpud0
#   [".gpud1"]         bash bench/perf/device_figures.sh part .gpud1
#   [".gpus0"]         bash bench/perf/device_figures.sh part .gpus0
#   [".gpus1"]         bash bench/perf/device_figures.sh part .gpus1
#   [".gpus2"]         bash bench/perf/device_figures.sh measure       # ~6 min; figures and logs come back in $OUT
# `measure` installs Warp, Open3D and Hydra, runs the CUDA tests, bench.perf.frames (new frames of the masked
# objects, both prior fills), bench.perf.stream on the sequence, the table3 experiment end to end twice (the first
# compiles the kernels; the second is the warm-cache figure) and bench.perf.overhead, all with --device cuda.
set -euo pipefail
root=$(git rev-parse --show-toplevel 2>/dev/null || pwd); cd "$root"
capture_files() {   # capture folder $1 -> $2: what the methods and metrics read (radar frames $3, no RGB)
  local c=$1 t=$2 frames=$3
  mkdir -p "$t/radar_72.0_82.0_128/calibrated_data" "$t/realsense" "$t/photogrammetry"
  cp "$c"/alignment.json "$c"/metadata.json "$t/"
  cp "$c"/radar_72.0_82.0_128/calibration.json "$t/radar_72.0_82.0_128/"
  for f in $frames; do cp "$c/radar_72.0_82.0_128/calibrated_data/$f.npy" "$t/radar_72.0_82.0_128/calibrated_data/"; done
  cp -r "$c"/realsense/depth "$c"/realsense/mask "$c"/realsense/calibration.json "$c"/realsense/timestamps.txt \
    "$t/realsense/"
  cp "$c"/photogrammetry/*.obj "$t/photogrammetry/"
  [ -f "$c/photogrammetry/cams.xml" ] && cp "$c/photogrammetry/cams.xml" "$t/photogrammetry/"
  [ -d "$c/photogrammetry/poses" ] && cp -r "$c/photogrammetry/poses" "$t/photogrammetry/"
  return 0
}
case "${1:-}" in
  pack)
    data=${2:-data/synthetic}
    exclude="$(git rev-parse --git-dir)/info/exclude"
    [ -d .wp0 ] && [ -d .o3d0 ] || bash ../shared/tools/device-parts.sh
    if [ ! -d .o3dc ]; then                          # Open3D's wheel in three parts of <= 36 MiB
      tmp=$(mktemp -d); cat .o3d0/o3d_* .o3d1/o3d_* > "$tmp/whl"; (cd "$tmp" && split -n 3 -d whl o3dp_)
      for i in 0 1 2; do d=.o3d$(echo abc | cut -c$((i + 1))); mkdir -p "$d"; mv "$tmp/o3dp_0$i" "$d/"
        grep -qx "/$d/" "$exclude" 2>/dev/null || echo "/$d/" >> "$exclude"; done
      cp .o3d1/WHEEL_NAME .o3dc/; rm -rf "$tmp"
    fi
    for d in .gpud0 .gpud1 .gpus0 .gpus1 .gpus2; do
      grep -qx "/$d/" "$exclude" 2>/dev/null || echo "/$d/" >> "$exclude"; rm -rf "$d"; mkdir -p "$d"
    done
    mapfile -t captures < <(find "$data" -mindepth 2 -maxdepth 2 -type d -name 30 | sort)
    for i in "${!captures[@]}"; do
      c=${captures[$i]}
      capture_files "$c" ".gpud$((i / 4))/cat/$(basename "$(dirname "$c")")/30" 000000
    done
    seq=${SEQ:-$(.venv/bin/python -c "from bench.perf.stream import default_sequence; print(default_sequence())")}
    capture_files "$seq" .gpus0/seq/04_bottle/30 "000000 000001 000002 000003"
    for part in "[4-7] .gpus1" "[8-9] .gpus2"; do      # the other radar frames
      set -- $part; frames="$2/seq/04_bottle/30/radar_72.0_82.0_128/calibrated_data"
      mkdir -p "$frames"; cp "$seq"/radar_72.0_82.0_128/calibrated_data/00000$1.npy "$frames/"
    done
    du -sh .gpud0 .gpud1 .gpus0 .gpus1 .gpus2 ;;
  part)
    mkdir -p /root/parts /root/data
    case "$2" in
      .gpud*|.gpus*) cp -r "$2"/* /root/data/ ;;
      *) cp "$2"/*_0* /root/parts/ 2>/dev/null || true; cp "$2"/WHEEL_NAME "/root/parts/$2.name" 2>/dev/null || true
         [ "$2" = .wp2 ] && cp .whl/*.whl /root/parts/
         [ "$2" = .o3dc ] && cp -r .gl /root/gl ;;
    esac
    ls /root/parts /root/data ;;
  measure)
    set +e +o pipefail                             # a failing step is logged; the next ones still run
    cp -r .gpus2/* /root/data/
    cat /root/parts/wp_* > "/tmp/$(cat /root/parts/.wp2.name)"
    cat /root/parts/o3dp_* > "/tmp/$(cat /root/parts/.o3dc.name)"
    python3 -m pip install -q --no-index --no-deps --no-compile --target /tmp/site "/tmp/$(cat /root/parts/.wp2.name)" \
      "/tmp/$(cat /root/parts/.o3dc.name)" /root/parts/*.whl
    for f in /root/gl/*.deb; do dpkg -x "$f" /; done; ldconfig
    export PYTHONPATH=/tmp/site:/root/gl/stubs:$PWD PYTHONUNBUFFERED=1 WARP_CACHE_PATH=/root/wpcache
    python3 -m pip install -q --no-deps --no-index --no-build-isolation -e . >/dev/null 2>&1 || true
    out=${OUT:-/tmp/out}; mkdir -p "$out"
    noise='^Module|^Warp|CUDA Toolkit|Devices:|"cpu"|"cuda:0"|Kernel cache'
    log="$out/measure.log"                         # one log: at most 8 files come back from the device
    nvidia-smi --query-gpu=name,driver_version --format=csv,noheader | tee "$log"
    python3 -m pytest -q -p no:cacheprovider -m cuda tests/methods/backends/test_gpu_frame_graph.py tests/methods/backends/test_gpu_fsk.py \
      tests/methods/backends/test_gpu_tables.py tests/methods/backends/test_gpu_hull_fill.py tests/methods/backends/test_gpu_prior_depth.py \
      tests/methods/test_correlate.py tests/methods/test_methods_api.py tests/methods/test_methods_conformance.py \
      2>&1 | tail -5 | tee -a "$log" || true                 # a failing test is reported; the figures still run
    python3 -m bench.perf.frames --device cuda --repeat "${REPEAT:-24}" --fill scanline delaunay --out "$out" 2>&1 \
      | grep -Ev "$noise" | tee -a "$log"
    python3 -m bench.perf.frames --device cuda --repeat "${REPEAT:-24}" --root /root/data/cat --out "$out/catalogue" \
      --cases mm2fsk:d10:realsense 2fsk:d05:none 3fsk:d05_d10:none 2>&1 | grep -Ev "$noise" | tee -a "$log"
    python3 -m bench.perf.stream --device cuda --root /root/data/seq --capture 04_bottle/30 --passes 3 --out "$out" \
      2>&1 | grep -Ev "$noise" | tee -a "$log"
    for run in cold warm; do
      start=$(date +%s%N)
      python3 -m bench -m experiment=table3 device=cuda hydra/launcher=basic dataset.root=/root/data/cat \
        store.dir=null hydra.sweep.dir=/tmp/table3_$run 2>&1 | grep -Ev "$noise" | tail -16
      echo "table3 $run: $(( ($(date +%s%N) - start) / 1000000 )) ms end to end"
    done 2>&1 | tee -a "$log"
    python3 -m bench.perf.overhead --root /root/data/cat --device cuda --out "$out" 2>&1 | grep -Ev "$noise" \
      | tail -20 | tee -a "$log" ;;
  *)
    echo "usage: bash bench/perf/device_figures.sh pack [ROOT] | part FOLDER | measure" >&2; exit 2 ;;
esac
