import numpy as np
import pytest

from ident.paper.duffing import DuffingParams
from ident.model import SindyModel


def eq8():
    return SindyModel.from_dict({"states": ["x1", "x2"], "degree": 3, "forcing": True,
                                 "equations": DuffingParams().true_coefficients()})


def test_equations_print_like_the_paper():
    assert eq8().equations(2) == ["x1' = 1.00 x2", "x2' = -1.00 x1 - 0.20 x2 - 0.60 x1^3 + 1.00 F"]


@pytest.mark.parametrize("fmt", ["json", "yaml"])
def test_round_trip(fmt):
    m = eq8()
    back = SindyModel.loads(m.dumps(fmt), fmt)
    np.testing.assert_array_equal(back.coefficients, m.coefficients)
    assert back.term_names == m.term_names


def test_table_layout():
    rows = eq8().table()
    assert rows[0] == ["1", 0.0, 0.0]
    assert rows[-1] == ["F", 0.0, 1.0]


@pytest.mark.parametrize("text,match", [
    ("{not json", "not valid"),
    ('{"states": ["x1"]}', "missing"),
    ('{"states": ["x1"], "degree": 1, "forcing": false, "equations": {"x1\'": {"x9": 1}}}', "unknown term"),
    ("[1, 2]", "mapping"),
])
def test_bad_model_text(text, match):
    with pytest.raises(ValueError, match=match):
        SindyModel.loads(text, "json")
