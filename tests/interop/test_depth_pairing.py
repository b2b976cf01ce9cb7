"""Which depth image goes with a label image (terrapref.interop.depth_pairing): the rule import
and the ROS nodes share."""

from __future__ import annotations

import pytest

from terrapref.interop.depth_pairing import DEPTH_PAIRING_S, DepthPairing


def test_a_label_image_takes_the_depth_image_of_the_nearest_stamp_within_50_ms_and_older_ones_go():
    pairing = DepthPairing(3)
    for t in (0.30, 0.10, 0.20, 0.26):  # out of order; three held at most, the oldest by stamp goes
        pairing.put(t, f"depth {t}")
    assert [s for s, _ in pairing.held] == [0.20, 0.26, 0.30] and pairing.newest_s == 0.30
    assert pairing.nearest(0.27) == (pytest.approx(0.01), "depth 0.26")  # 10 ms before it, 30 ms after
    assert [s for s, _ in pairing.held] == [0.26, 0.30]  # 0.20 is too old for any label image to come
    assert pairing.settled(0.30) and not pairing.settled(0.31)  # a nearer one may come for an image at 0.31
    assert DEPTH_PAIRING_S == 0.05 and pairing.nearest(0.36) is None  # 60 ms from the newest
    assert pairing.held == []
