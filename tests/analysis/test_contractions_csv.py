"""The contractions CSV's table helpers: what a model is driven with through the frames that
were not measured."""

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from myoface.analysis.contractions_csv import hold_last_measured

tables = st.integers(1, 4).flatmap(
    lambda m: arrays(
        np.float64,
        st.tuples(st.integers(0, 12), st.just(m)),
        elements=st.sampled_from([np.nan, 0.0, 0.25, 1.0]) | st.floats(0, 1),
    )
)


@given(tables)
def test_hold_last_measured_drives_the_model_through_unmeasured_rows(table):
    """A row with any NaN (not measured) becomes the last measured row before it (zeros before
    the first); measured rows stay as they were; nothing is NaN after; the input is left
    alone."""
    before = table.copy()
    out = hold_last_measured(table)
    assert out.shape == table.shape and not np.isnan(out).any()
    np.testing.assert_array_equal(table, before)
    last = np.zeros(table.shape[1])
    for k, row in enumerate(table):
        if np.isnan(row).any():
            np.testing.assert_array_equal(out[k], last)
        else:
            np.testing.assert_array_equal(out[k], row)
            last = row


def test_hold_last_measured_example():
    t = np.array([[np.nan, np.nan], [0.2, 0.3], [np.nan, 0.5], [0.4, 0.1]])
    np.testing.assert_array_equal(
        hold_last_measured(t), [[0, 0], [0.2, 0.3], [0.2, 0.3], [0.4, 0.1]]
    )
