"""Light-code synchronisation: synthetic brightness signals (frame rates, offsets, drift,
exposure, missing and disagreeing codes) and rendered videos against their truth."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from calibproj import _core
from calibproj.sequence.builder import build_sequence
from calibproj.ingest.videos import ingest, luma_signal, synchronise
from calibproj.ingest.options import IngestOptions
from calibproj.simulate.render import simulate_videos
from calibproj.simulate.scene import load_scene

PROJECTOR_FPS = 30.0
# The goal: sub-frame sync, well inside the frame picking margin.
MAX_SYNC_ERROR_FRAMES = 0.1


def short_sequence(**overrides):
    """Three arrays at two scales and 15-bit codes: about 200 projector frames."""
    options = {"arrays": 3, "scales": (1.0, 2.0), "grid": (2, 4), "code_degree": 4, "reference_frames": 8}
    return build_sequence(**{**options, **overrides})


def projector_light(sequence, rng) -> np.ndarray:
    """Level of every projector frame; patterns get random brightness of their own."""
    levels = _core.ingest.light_levels(sequence)
    for pattern in sequence.patterns:
        levels[pattern.first_frame:pattern.last_frame + 1] = rng.uniform(0.05, 0.3)
    return levels


def camera_signal(light, offset, rate, exposure, frames, rng, noise=0.002, black=0.08, contrast=0.6):
    """Mean brightness a camera records: frame j integrates the light over
    [(j - offset) / rate, ... + exposure / rate) projector frames (black outside)."""
    cumulative = np.concatenate([[0.0], np.cumsum(light)])

    def integral(t):
        t = np.clip(t, 0.0, len(light))
        k = np.minimum(t.astype(int), len(light) - 1)
        return cumulative[k] + (t - k) * light[k]

    start = (np.arange(frames) - offset) / rate
    duration = exposure / rate
    mean = (integral(start + duration) - integral(start)) / duration
    return black + contrast * mean + rng.normal(0.0, noise, frames)


def record(sequence, fps, offset, exposure, rng, drift=0.0, **kwargs):
    rate = fps / PROJECTOR_FPS * (1.0 + drift)
    frames = int(offset + rate * sequence.frame_count + 20)
    return camera_signal(projector_light(sequence, rng), offset, rate, exposure, frames, rng, **kwargs), rate


def known_exposure(exposure_frames, fps):
    return IngestOptions(exposure_s=exposure_frames / fps)


# Light changes fall on the sequence's 3-frame bit grid. A 25 fps camera samples them at
# two phases half a frame apart, and a 29.97 fps one at drifting phases: frames across
# changes then fix both the offset and the exposure. At 30 and 60 fps every change
# falls at the same phase of the camera's frames, and a frame across one only tells how
# its exposure splits: the offset follows once the exposure is known. Exposures (camera
# frames) are long enough that some frame spans a change whatever the offset.
@pytest.mark.parametrize("fps, exposure, known", [
    (25.0, 0.5, False), (29.97, 1.0, False), (30.0, 1.0, True), (60.0, 1.0, True),
])
def test_sync_error_is_below_a_tenth_of_a_frame(fps, exposure, known):
    sequence = short_sequence()
    rng = np.random.default_rng(int(fps * 100))
    options = known_exposure(exposure, fps) if known else IngestOptions()
    for offset in rng.uniform(3.0, 60.0, 4):
        signal, rate = record(sequence, fps, offset, exposure, rng)
        result = synchronise(signal, sequence, fps, options)
        assert abs(result.map.offset - offset) < MAX_SYNC_ERROR_FRAMES
        assert abs(result.map.rate / rate - 1.0) < 2e-4
        assert result.offset_uncertainty < MAX_SYNC_ERROR_FRAMES
        assert abs(result.map.exposure - exposure) < 0.1


def test_clock_drift_is_measured():
    sequence = short_sequence()
    rng = np.random.default_rng(5)
    nominal = 30.0 / PROJECTOR_FPS
    for drift in (-400e-6, 250e-6):
        signal, rate = record(sequence, 30.0, 17.3, 1.0, rng, drift=drift)
        result = synchronise(signal, sequence, 30.0, known_exposure(1.0, 30.0))
        assert abs(result.map.offset - 17.3) < MAX_SYNC_ERROR_FRAMES
        # 0.005 frame over the ~140 frames between the codes of this short sequence.
        assert (result.map.rate / nominal - 1.0) == pytest.approx(drift, abs=6e-5)


def test_bands_fitted_together_give_each_band_its_own_fit():
    """The readout's band fits share the light predicted for the frames bands have in
    common, scanned along with the first band of their group; a band with gaps of its
    own is fitted apart. Whatever the order of the bands, and so whichever band leads a
    group, each band's fit is the same to the last bit."""
    sequence = short_sequence()
    rng = np.random.default_rng(11)
    light = projector_light(sequence, rng)
    rate = 25.0 / PROJECTOR_FPS
    frames = int(9.0 + rate * len(light) + 20)
    bands = np.stack([camera_signal(light, 9.0 + 0.03 * b, rate, 0.5, frames, rng) for b in range(4)])
    bands[2, ::7] = np.nan
    levels = np.asarray(_core.ingest.light_levels(sequence))
    start_map = _core.sync.FrameMap(9.0, rate, 0.5)

    def fits(order):
        estimate = _core.sync.estimate_readout(bands[order], levels, sequence.start_code, sequence.end_code, start_map)
        return [(band.offset, band.sigma, band.rms) for band in estimate.bands]

    in_order = fits([0, 1, 2, 3])
    assert len(in_order) == 4
    for order in ([3, 2, 1, 0], [2, 0, 1, 3], [1, 3, 0, 2]):
        assert fits(order) == [in_order[b] for b in order], order


def test_a_search_grid_too_fine_to_keep_is_refused():
    """The fit keeps every band's cost at every (offset, exposure) point searched: a grid
    of more than two million points is refused before any work, with the knobs named."""
    sequence = short_sequence()
    signal, _ = record(sequence, 25.0, 10.0, 0.5, np.random.default_rng(1))
    with pytest.raises(ValueError, match="offset_step and exposure_steps make more than 2000000"):
        synchronise(signal, sequence, 25.0, IngestOptions(offset_step=0.0001))


@pytest.mark.parametrize("missing", [0.02, 0.1])
def test_codes_are_found_over_frames_the_camera_dropped(missing):
    """Dropped frames are NaN on the frame grid: codes are searched and fitted over the
    frames present; more missing than max_missing_share and the code is not found."""
    sequence = short_sequence()
    rng = np.random.default_rng(11)
    signal, _ = record(sequence, 25.0, 23.6, 0.5, rng)
    signal[1:][rng.random(len(signal) - 1) < missing] = np.nan
    result = synchronise(signal, sequence, 25.0)
    assert abs(result.map.offset - 23.6) < MAX_SYNC_ERROR_FRAMES
    with pytest.raises(RuntimeError, match="start light code"):
        synchronise(signal, sequence, 25.0, IngestOptions(max_missing_share=missing / 20))


def test_short_exposure_truth_lies_within_the_reported_uncertainty():
    """At the projector's rate with a short exposure no frame may span a light change:
    the offset is then known only to an interval, which must hold the truth, and the
    conservative window map must cover the true exposure windows."""
    sequence = short_sequence()
    rng = np.random.default_rng(11)
    exposure = 0.3
    for offset in rng.uniform(3.0, 60.0, 6):
        signal, rate = record(sequence, 30.0, offset, exposure, rng)
        result = synchronise(signal, sequence, 30.0)
        assert abs(result.map.offset - offset) <= result.offset_uncertainty + 1e-9
        window = result.window_map
        assert window.offset >= offset - 1e-6  # windows start no later than the truth's
        assert window.exposure - window.offset >= exposure - offset - 1e-6  # and end no earlier
        if result.sharp:
            assert abs(result.map.offset - offset) < MAX_SYNC_ERROR_FRAMES


def test_correlation_peaks_at_the_code():
    sequence = short_sequence()
    rng = np.random.default_rng(2)
    signal, _ = record(sequence, 25.0, 12.4, 0.5, rng)
    levels = _core.ingest.light_levels(sequence)
    start = _core.sync.locate_code(signal, levels, sequence.start_code, 25.0 / PROJECTOR_FPS)
    expected = 12.4 + 25.0 / PROJECTOR_FPS * sequence.start_code.first_frame
    assert start.correlation > 0.99
    assert abs(start.frame - expected) < MAX_SYNC_ERROR_FRAMES


def test_a_missing_code_is_an_error_with_the_best_correlation():
    sequence = short_sequence()
    rng = np.random.default_rng(3)
    noise = rng.normal(0.3, 0.05, 400)
    with pytest.raises(RuntimeError, match=r"cam9: start light code not found: best correlation 0\.\d+"):
        synchronise(noise, sequence, 30.0, source="cam9")


def test_codes_of_another_sequence_disagree():
    """A recording of a longer sequence: both codes are found, too far apart."""
    recorded = short_sequence(arrays=5)
    rng = np.random.default_rng(4)
    signal, _ = record(recorded, 30.0, 9.0, 1.0, rng)
    with pytest.raises(RuntimeError, match="cam2: the start and end light codes disagree"):
        synchronise(signal, short_sequence(), 30.0, source="cam2")


def test_a_truncated_recording_is_an_error():
    sequence = short_sequence()
    rng = np.random.default_rng(6)
    signal, rate = record(sequence, 30.0, 9.0, 1.0, rng)
    cut = int(9.0 + rate * (sequence.end_code.first_frame - 10))
    with pytest.raises(RuntimeError, match="end light code not found"):
        synchronise(signal[:cut], sequence, 30.0, source="cam1")


# ------------------------------------------------------------------ rendered videos

def sync_scene():
    """Tiny cameras at every frame rate that must work, with arbitrary start offsets and
    exposures long enough that some frame spans a light change (see above), plus one
    with a short exposure."""
    small = load_scene("small")
    tiny = {"resolution": (160, 90), "fx": 76.25, "fy": 76.25, "cx": 79.5, "cy": 44.5, "dist": (0.0,) * 5}
    base = replace(small.cameras[0], **tiny)
    cameras = (
        replace(base, name="c25", fps=25.0, start_offset_s=0.5371, exposure_s=0.02),
        replace(base, name="c30", fps=30.0, start_offset_s=0.8123, exposure_s=1 / 30),
        replace(base, name="c60", fps=60.0, start_offset_s=0.2468, exposure_s=1 / 60),
        replace(base, name="c2997", fps=29.97, start_offset_s=1.0931, exposure_s=1 / 30),
        replace(base, name="short30", fps=30.0, start_offset_s=0.6217, exposure_s=0.008),
    )
    return replace(small, cameras=cameras)


# Cameras whose exposure the sync is told (see test_sync_error_is_below_a_tenth_of_a_frame).
KNOWN_EXPOSURES = {"c30": 1 / 30, "c60": 1 / 60}


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    out = tmp_path_factory.mktemp("sync_render")
    sequence = short_sequence(scales=(4.0,), arrays=2)
    simulate_videos(sync_scene(), sequence, out, seed=1)
    return out, sequence, json.loads((out / "truth.json").read_text())


def true_map(truth, name):
    timing = truth["timing"]["cameras"][name]
    fps = timing["fps"]
    return -timing["first_exposure_start_s"] * fps, fps / PROJECTOR_FPS, timing["exposure_s"] * fps


def test_rendered_videos_synchronise_to_a_tenth_of_a_frame(rendered):
    out, sequence, truth = rendered
    for name in ("c25", "c30", "c60", "c2997", "short30"):
        offset, rate, exposure = true_map(truth, name)
        fps = truth["timing"]["cameras"][name]["fps"]
        options = IngestOptions(exposure_s=KNOWN_EXPOSURES.get(name, 0.0))
        result = synchronise(luma_signal(out / "videos" / f"{name}.mp4"), sequence, fps, options, source=name)
        error = abs(result.map.offset - offset)
        assert abs(result.map.rate / rate - 1.0) < 1e-4, name
        if name == "short30":  # no frame across a light change: an interval
            assert error <= result.offset_uncertainty, name
        else:
            assert error < MAX_SYNC_ERROR_FRAMES, name


def test_ingest_synchronises_while_decoding(rendered):
    """The ingest finds the start code incrementally, measures the end code only where it
    must be and decodes nothing after it: the same sync as the whole signal gives."""
    out, sequence, truth = rendered
    result = ingest(out / "videos", sequence, out / "intrinsics", progress=False, exposures=KNOWN_EXPOSURES)
    assert not result.failed
    for name, camera in result.cameras.items():
        offset, rate, _ = true_map(truth, name)
        sync = camera.raw.sync
        assert abs(sync.map.offset - offset) <= max(MAX_SYNC_ERROR_FRAMES, sync.offset_uncertainty), name
        assert abs(sync.map.rate / rate - 1.0) < 1e-4, name
        assert len(camera.raw.signal) < truth["timing"]["cameras"][name]["recorded_frames"], name


def automatic_exposure(signal, target, time_constant_s, fps):
    """What a camera adjusting its gain after every frame towards ``target`` records."""
    step = 1.0 - np.exp(-1.0 / (fps * time_constant_s))
    gain, out = 1.0, []
    for value in signal:
        out.append(gain * value)
        gain = float(np.clip(gain * (target / max(gain * value, 1e-3)) ** step, 0.25, 8.0))
    return np.array(out)


def test_a_camera_adjusting_its_exposure_during_the_code_still_finds_it():
    """A camera started with the projection whose fast automatic exposure (0.15 s)
    answers every light change: the code's correlation falls below the threshold unless
    signal and code are detrended. The fit's linear gain drift then places it within a
    frame (half a frame here): automatic exposure costs sync accuracy, not the camera."""
    sequence = short_sequence()
    rng = np.random.default_rng(9)
    offset = 2.6
    signal, _ = record(sequence, 30.0, offset, 1.0, rng)
    signal = automatic_exposure(signal, 0.45, 0.15, 30.0)
    options = known_exposure(1.0, 30.0)
    with pytest.raises(RuntimeError, match="light code not found"):
        synchronise(signal, sequence, 30.0, options.replace(detrend_frames=0))
    result = synchronise(signal, sequence, 30.0, options)
    assert abs(result.map.offset - offset) < 1.0
