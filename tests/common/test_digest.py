"""The cache keys' digest (harness/common/digest.py): alike only when alike."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

from mbh._harness.common.digest import feed
from mbh._harness.model.mechanism import InitialState


def _hex(value) -> str:
    digest = hashlib.sha256()
    feed(digest, value)
    return digest.hexdigest()


def test_type_shape_and_structure_count():
    assert _hex(np.zeros(2)) != _hex(np.zeros((2, 1))) != _hex(np.zeros(2, dtype=np.float32))
    assert _hex((1, 2)) != _hex(((1,), 2)) and _hex(1) != _hex(1.0) != _hex("1")
    assert _hex({"b": 1, "a": 2}) == _hex({"a": 2, "b": 1}) != _hex({"a": 1, "b": 2})
    assert _hex(InitialState(driver="a", value=0.0, rate=1.0)) \
        != _hex(InitialState(driver="a", value=0.0, rate=-1.0))


def test_a_value_without_a_faithful_digest_is_refused():
    with pytest.raises(TypeError):
        feed(hashlib.sha256(), np.array([object()]))
    with pytest.raises(TypeError):
        feed(hashlib.sha256(), {1, 2})
