#!/usr/bin/env bash
# Every GPU figure of notes/gpu.md (round 9) on the device machine, in four calls of the `run` tool (a call carries
# at most 64 MiB: the Warp wheel and the 8 catalogue captures travel in quarters). Here, once:
#   bash bench/device_figures.sh pack [ROOT]       # ROOT: dataset root (default data/synthetic, 30 cm captures)
# then on the device, back to back (each `carry` names one folder):
#   carry [".gpu0"]: bash bench/device_figures.sh part 0
#   carry [".gpu1"]: bash bench/device_figures.sh part 1
#   carry [".gpu2"]: bash bench/device_figures.sh part 2
#   carry [".gpu3"]: bash bench/device_figures.sh measure      # ~3-4 min: CUDA tests, then bench.perf_skips_gpu
# `measure` installs Warp, runs the CUDA tests of the GPU code and `python -m bench.perf_skips_gpu` on the 8
# captures (new frames, roi=auto beside roi=none, median and p90), and leaves the CSV and logs under $OUT.
set -euo pipefail
root=$(git rev-parse --show-toplevel 2>/dev/null || pwd); cd "$root"
case "${1:-}" in
  pack)
    data=${2:-data/synthetic}
    exclude="$(git rev-parse --git-dir)/info/exclude"
    tmp=$(mktemp -d)
    python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
      --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 -d "$tmp" "warp-lang==${WARP_VERSION:-1.19.0}"
    whl=$(basename "$tmp"/warp_lang-*.whl)
    (cd "$tmp" && split -n 4 -d "$whl" part_)
    mapfile -t captures < <(find "$data" -mindepth 2 -maxdepth 2 -type d -name 30 | sort)
    for i in 0 1 2 3; do
      d=.gpu$i
      grep -qx "/$d/" "$exclude" 2>/dev/null || echo "/$d/" >> "$exclude"
      rm -rf "$d"; mkdir -p "$d/data"; mv "$tmp/part_0$i" "$d/"; echo "$whl" > "$d/WHEEL_NAME"
      for c in "${captures[@]:$((2 * i)):2}"; do       # radar frame 0 + RealSense parts: what the methods read
        t="$d/data/$(basename "$(dirname "$c")")/30"
        mkdir -p "$t/radar_72.0_82.0_128/calibrated_data" "$t/realsense/depth" "$t/realsense/mask"
        cp "$c"/alignment.json "$c"/metadata.json "$t/"
        cp "$c"/radar_72.0_82.0_128/calibration.json "$t/radar_72.0_82.0_128/"
        cp "$c"/radar_72.0_82.0_128/calibrated_data/000000.npy "$t/radar_72.0_82.0_128/calibrated_data/"
        cp "$c"/realsense/calibration.json "$c"/realsense/timestamps.txt "$t/realsense/"
        cp "$c"/realsense/depth/000000.png "$t/realsense/depth/"
        cp "$c"/realsense/mask/000000.png "$t/realsense/mask/"
      done
    done
    rm -rf "$tmp"; du -sh .gpu0 .gpu1 .gpu2 .gpu3 ;;
  part)
    mkdir -p /root/parts /root/data
    cp ".gpu$2"/part_* /root/parts/ && cp -r ".gpu$2"/data/* /root/data/ && ls /root/data ;;
  measure)
    cp .gpu3/part_* /root/parts/ && cp -r .gpu3/data/* /root/data/
    cat /root/parts/part_* > "/tmp/$(cat .gpu3/WHEEL_NAME)"
    python3 -m pip install -q --no-index --no-deps --no-compile --target /tmp/site "/tmp/$(cat .gpu3/WHEEL_NAME)"
    export PYTHONPATH=/tmp/site PYTHONUNBUFFERED=1 WARP_CACHE_PATH=/root/wpcache
    out=${OUT:-/tmp/out}; mkdir -p "$out"
    noise='^Module|^Warp|CUDA Toolkit|Devices:|"cpu"|"cuda:0"|Kernel cache'
    nvidia-smi --query-gpu=name,driver_version --format=csv,noheader | tee "$out/device.txt"
    python3 -m pytest -q -p no:cacheprovider -m cuda tests/test_gpu_hull_fill.py tests/test_gpu_range_points.py \
      tests/test_gpu_prior_depth.py tests/test_correlate.py tests/test_methods_api.py 2>&1 | tail -5 | tee "$out/tests.log" \
      || true                                                # a failing test is reported; the figures still run
    python3 -m bench.perf_skips_gpu --root /root/data --device cuda --repeat "${REPEAT:-5}" --out "$out" 2>&1 \
      | grep -Ev "$noise" | tee "$out/perf_skips_gpu.log" ;;
  *)
    echo "usage: bash bench/device_figures.sh pack [ROOT] | part 0|1|2 | measure" >&2; exit 2 ;;
esac
