import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.signal import sosfreqz

from ident.filters import (decimate_block, design_lowpass, lowpass_block, lowpass_start,
                           lowpass_zero_phase)

FS = 2000.0


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(min_value=0, max_value=700), min_size=1, max_size=12), st.integers(0, 10**6))
def test_any_split_into_blocks_equals_the_one_shot_filter(sizes, seed):
    rng = np.random.default_rng(seed)
    x = rng.standard_normal((sum(sizes), 3))
    sos = design_lowpass(FS)
    _, whole = lowpass_block(lowpass_start(sos, 3), x)
    state, parts, pos = lowpass_start(sos, 3), [], 0
    for k in sizes:
        state, y = lowpass_block(state, x[pos:pos + k])
        parts.append(y)
        pos += k
    np.testing.assert_allclose(np.concatenate(parts), whole, rtol=0, atol=1e-12)


def test_response_at_and_around_50_hz():
    sos = design_lowpass(FS, 50.0, order=4)
    w, h = sosfreqz(sos, worN=[12.3, 50.0, 250.0], fs=FS)
    assert abs(h[0]) == pytest.approx(1.0, abs=1e-4)  # the rig's 12.3 Hz passes
    assert abs(h[1]) == pytest.approx(1 / np.sqrt(2), rel=1e-3)  # -3 dB at the cut-off
    assert 20 * np.log10(abs(h[2])) < -4 * 20 * np.log10(5) + 1  # 4th order: -80 dB/decade


def test_zero_phase_keeps_the_phase_of_a_12_hz_sine():
    t = np.arange(4000) / FS
    x = np.sin(2 * np.pi * 12.3 * t) + 0.5 * np.sin(2 * np.pi * 300 * t)
    y = lowpass_zero_phase(x, FS)
    inner = slice(500, -500)
    np.testing.assert_allclose(y[inner], np.sin(2 * np.pi * 12.3 * t)[inner], atol=2e-3)


def test_decimation_is_block_split_invariant():
    x = np.arange(103)
    off, out = 0, []
    for k in (7, 1, 30, 65):
        off, y = decimate_block(off, x[off:off + k], 10)
        out.append(y)
    assert np.concatenate(out).tolist() == list(range(0, 103, 10))


def test_bad_input():
    with pytest.raises(ValueError, match="Nyquist"):
        design_lowpass(80.0, 50.0)
    with pytest.raises(ValueError, match="NaN"):
        lowpass_block(lowpass_start(design_lowpass(FS), 1), np.array([[1.0], [np.nan]]))


@pytest.mark.parametrize("shape", [(8000, 3), (1600,), (1600, 2)])
def test_zero_phase_is_scipys_sosfiltfilt(shape):
    """The cached-initial-condition forward-backward filter gives scipy's sosfiltfilt exactly."""
    from scipy.signal import sosfiltfilt

    from ident.filters import design_highpass, zero_phase

    x = np.random.default_rng(3).normal(size=shape)
    for sos in (design_lowpass(2000.0, 50.0), design_highpass(400.0, 2.0, 2)):
        np.testing.assert_array_equal(zero_phase(sos, x), sosfiltfilt(sos, x, axis=0))


def test_block_filter_is_scipys_sosfilt():
    """The causal filter's compiled kernel gives scipy's sosfilt bit for bit, its state carried across blocks,
    from rest and settled at the first sample."""
    from scipy.signal import sosfilt, sosfilt_zi

    x = np.random.default_rng(4).normal(size=(1500, 3)) + 2.0
    sos = design_lowpass(FS)
    for first in (None, x[0]):
        state = lowpass_start(sos, 3, first)
        zi = np.zeros((sos.shape[0], 2, 3)) if first is None else sosfilt_zi(sos)[:, :, None] * x[0]
        state, a = lowpass_block(state, x[:700])
        state, b = lowpass_block(state, x[700:])
        ref, zf = sosfilt(sos, x, axis=0, zi=zi)
        np.testing.assert_array_equal(np.concatenate([a, b]), ref)
        np.testing.assert_array_equal(state.zi, zf)
