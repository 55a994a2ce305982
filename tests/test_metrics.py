import numpy as np
import pytest

from ident.metrics import error_percent, nrmse, snr_db


def test_snr_of_a_sine_with_known_noise_power():
    t = np.linspace(0, 32 * np.pi, 200000, endpoint=False)  # 16 whole periods
    clean = 2.0 * np.sin(t)  # power A^2 / 2 = 2
    noise = np.full_like(t, 0.2)
    noise[1::2] = -0.2  # power exactly 0.04
    assert snr_db(clean, clean + noise) == pytest.approx(10 * np.log10(2 / 0.04), abs=1e-3)


def test_error_metric_is_a_deviation_and_blind_to_phase():
    t = np.linspace(0, 20 * np.pi, 10001)
    clean = np.sin(t)
    assert error_percent(clean, clean) == 0.0
    assert error_percent(clean, 1.1 * clean) == pytest.approx(10.0)
    shifted = np.sin(t + np.pi)
    assert error_percent(clean, shifted) == pytest.approx(0.0, abs=1e-6)
    assert nrmse(clean, shifted) == pytest.approx(2.0, rel=1e-3)  # NRMSE sees the phase


def test_diverged_reconstruction_scores_inf_and_shape_mismatch_raises():
    assert error_percent(np.arange(5.0), np.array([0, 1, np.nan, 3, 4.0])) == np.inf
    with pytest.raises(ValueError, match="shapes"):
        nrmse(np.ones(3), np.ones(4))
    with pytest.raises(ValueError, match="constant"):
        nrmse(np.ones(3), np.ones(3))
