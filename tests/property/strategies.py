"""Hypothesis strategies of the odd values a user may pass anywhere."""

from __future__ import annotations

import numpy as np
from hypothesis import strategies as st

#: Floats of every kind: NaN, infinities, zero, negatives, huge and tiny magnitudes.
any_float = st.floats(allow_nan=True, allow_infinity=True, width=64)

#: Integers of every width, Python's and NumPy's.
any_integer = st.one_of(
    st.integers(min_value=-(2**70), max_value=2**70),
    st.integers(min_value=-(2**7), max_value=2**7 - 1).map(np.int8),
    st.integers(min_value=0, max_value=2**16 - 1).map(np.uint16),
    st.integers(min_value=-(2**31), max_value=2**31 - 1).map(np.int32),
    st.integers(min_value=-(2**63), max_value=2**63 - 1).map(np.int64),
    st.integers(min_value=0, max_value=2**64 - 1).map(np.uint64),
)

#: Anything a user might pass by mistake: None, bools, strings, numbers, containers.
odd_value = st.one_of(
    st.none(),
    st.booleans(),
    st.text(max_size=8),
    any_float,
    any_integer,
    st.lists(any_float, max_size=4),
    st.tuples(any_integer, any_integer),
    st.dictionaries(st.text(max_size=3), st.integers(), max_size=2),
    st.just(object()),
    st.just(np.zeros((2, 2))),
)
