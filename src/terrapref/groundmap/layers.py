"""The layers a ground map holds over its grid (:data:`LAYERS`), each named and typed.

Every layer is an array over the same square of cells (rows y, columns x), moved with it when
the map is re-centred and emptied with it when the map is reset. A new layer (a height from a
depth sensor, say) is one more entry in :data:`LAYERS` plus the code that writes it; the rules
read the layers they need and are not touched.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Layer:
    """One layer of a ground map.

    Attributes:
        name: what the map calls it (``GroundMap.layer(name)``).
        dtype: the type of its values.
        fill: the value of a cell nothing was written to (the map's start, a cell newly come
            into the square); ignored with ``fill_unseen``.
        per_column: one value per terrain column (K + 1: the K terrain classes and the
            background) in each cell, (n, n, K + 1), instead of one per cell, (n, n).
        fill_unseen: the fill is the column of ground never seen, K + 1.
        values: this many values in each cell, (n, n, values), where more than one (and not
            ``per_column``).
        from_depth: written from depth images alone (the heights, the ground's shape and what
            is read from it): a map that has read none, and handed none out, holds it empty,
            and a re-centre leaves it as it is (moved, an empty layer reads the same).
    """

    name: str
    dtype: type
    fill: float = 0
    per_column: bool = False
    fill_unseen: bool = False
    values: int = 1
    from_depth: bool = False

    def fill_value(self, k: int) -> float:
        """The value of an empty cell, for a map of ``k`` terrain columns."""
        return k + 1 if self.fill_unseen else self.fill

    def empty(self, n: int, k: int) -> np.ndarray:
        """The layer of a map of ``n`` by ``n`` cells and ``k`` terrain columns with nothing written."""
        shape = (n, n, k + 1) if self.per_column else (n, n, self.values) if self.values > 1 else (n, n)
        return np.full(shape, self.fill_value(k), dtype=self.dtype)


LAYERS: tuple[Layer, ...] = (
    # Each cell's terrain column (0..K-1, K the background, K + 1 never seen), or
    # terrapref.groundmap.map_compiled.UNSETTLED where voted on since it was last decided.
    Layer("column", np.uint8, fill_unseen=True),
    # Each cell's votes per column, faded with the frames since its last vote (map_compiled.map_vote).
    Layer("evidence", np.float32, 0.0, per_column=True),
    # The frame of each cell's last vote (its fading is counted from it).
    Layer("stamp", np.int64, 0),
    # The mean height of the depth returns that fell in each cell [m], NaN where none did, each
    # weighed by the inverse of its variance (terrapref.groundmap.height), how many did, their
    # weighted sum of squared deviations, and their weights' sum [1 / m^2].
    Layer("elevation", np.float32, np.nan, from_depth=True),
    Layer("returns", np.uint32, 0, from_depth=True),
    Layer("spread", np.float32, 0.0, from_depth=True),
    Layer("weight", np.float32, 0.0, from_depth=True),
    # The ground's shape, as each frame alone shows it, fused over frames
    # (terrapref.groundmap.height_compiled.depth_frame): each cell's height difference to its
    # neighbour along x and the run between their returns along x, each the mean of the frames'
    # weighed by the inverse of its variance [m], the weights' sum [1 / m^2], and likewise along
    # y (height_compiled.SHAPE_VALUES: one cell's six together, as the kernels read them). What
    # its slope and steps are read from.
    Layer("shape", np.float32, 0.0, values=6, from_depth=True),
    # The differences along x and y as the cells round each were last read (NaN: not known then;
    # +inf: never read), so that only the cells round a changed one are read again, and the runs
    # read with them (NaN where the difference is not a number).
    Layer("checked_dx", np.float32, np.inf, from_depth=True),
    Layer("checked_dy", np.float32, np.inf, from_depth=True),
    Layer("checked_dx_run", np.float32, np.nan, from_depth=True),
    Layer("checked_dy_run", np.float32, np.nan, from_depth=True),
    # Over the disc round each cell its slope is read over, the sums of those read differences
    # and runs and how many are known, along x and then y (height_compiled.DISC_SUMS): kept up to
    # date as the differences are read, so that a cell's gradient is two quotients.
    Layer("disc", np.float32, 0.0, values=6, from_depth=True),
    # The ground's roughness as each frame alone shows it, fused over frames
    # (terrapref.groundmap.height_compiled.depth_frame): the weighted mean of the frames' squared
    # roughness less what their depth noise adds [m^2], and the weights' sum (0: never read).
    Layer("rough", np.float32, 0.0, from_depth=True),
    Layer("rough_weight", np.float32, 0.0, from_depth=True),
    # 1 where the ground's geometry is past the vehicle's limits (terrapref.groundmap.height):
    # the cell reads as lethal whatever its evidence.
    Layer("blocked", np.uint8, 0, from_depth=True),
)
"""The ground map's layers, in the order they are made (module docstring)."""
