"""python -m bench.perf synth: the `direct` path computes every frequency and is undone afterwards; the frame
comparison reports the largest difference over the peak."""
import numpy as np

from bench.perf.synth import frame_difference, radar_path
from bench.synth.config import SynthConfig
from bench.synth.radar import frequency_nodes

FREQS_HZ = np.linspace(72e9, 82e9, 128)


def test_direct_path_computes_every_frequency_and_is_restored():
    assert frequency_nodes.interpolator(FREQS_HZ, 0.01)[1] is not None
    with radar_path("direct"):
        nodes_hz, fit = frequency_nodes.interpolator(FREQS_HZ, 0.01)
        assert fit is None and np.array_equal(nodes_hz, FREQS_HZ)
    assert frequency_nodes.interpolator(FREQS_HZ, 0.01)[1] is not None


def test_frame_difference_is_relative_to_the_peak(tmp_path):
    frame = np.full((2, 2, 3), 2.0 + 0j, dtype=np.complex64)
    for name, xr in (("nodes", frame + np.complex64(1e-3)), ("direct", frame)):
        folder = tmp_path / name / "radar_72.0_82.0_3" / "calibrated_data"
        folder.mkdir(parents=True)
        np.save(folder / "000000.npy", {"xr": xr})
    difference = frame_difference(tmp_path / "nodes", tmp_path / "direct", SynthConfig())
    assert abs(difference["max_diff_over_peak"] - 5e-4) < 1e-6
    assert np.isnan(difference["rms_diff_over_noise_db"])          # the ideal preset's noise is relative (snr)


def test_catalogue_timing_builds_with_the_builders_asked_for_and_restores_the_defaults(tmp_path):
    from bench.perf.synth import catalogue
    from bench.synth import workers

    defaults = workers.capture_workers, workers.capture_processes
    row = catalogue(["01_plate"], 30, SynthConfig(frequency_points=16), 2, tmp_path, builders="threads")
    assert row["builders"] == "threads" and row["workers"] == 2 and row["captures"] == 1 and row["wall_s"] > 0
    assert (workers.capture_workers, workers.capture_processes) == defaults
    assert len(list(tmp_path.glob("workers2-*/01_plate/30/radar_72.0_82.0_16/calibrated_data/*.npy"))) == 2
