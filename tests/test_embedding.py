import numpy as np
import pytest

from ident.embedding import acf_delay, delay_embed, embed, fnn_dimension


@pytest.mark.parametrize("period", [40, 200, 360])
def test_acf_delay_is_a_quarter_period_for_a_sine(period):
    n = 20 * period
    x = np.sin(2 * np.pi * np.arange(n) / period)
    assert acf_delay(x) == pytest.approx(period / 4, abs=1)


def test_fnn_dimension_of_a_sine_is_two():
    x = np.sin(2 * np.pi * np.arange(4000) / 200)
    m, fr = fnn_dimension(x, acf_delay(x))
    assert m == 2 and fr[0] > 0.2


def test_fnn_dimension_of_the_lorenz_attractor_is_three(lorenz):
    _, x, _ = lorenz
    xs = x[2500::5, 0]  # dt = 0.01 on the attractor
    m, fr = fnn_dimension(xs, 10)  # tau = 0.1, the usual delay for Lorenz x
    assert m == 3
    assert fr[1] > 0.02  # two dimensions are not enough


def test_duffing_embedding_next_to_the_paper(duffing):
    emb = embed(duffing.x[:, 0])
    assert emb.dimension == 3  # paper: m = 3
    assert abs(emb.delay - 127) <= 5  # paper: d = 127
    np.testing.assert_array_equal(emb.states[0], duffing.x[[2 * emb.delay, emb.delay, 0], 0])


def test_too_short_or_constant_series_raise():
    with pytest.raises(ValueError, match="too short"):
        delay_embed(np.arange(20.0), 10, 3)
    with pytest.raises(ValueError, match="constant"):
        embed(np.ones(100))
