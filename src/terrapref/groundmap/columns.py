"""How a class table's classes fall into the terrain columns that U and the ground map count."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from terrapref.terrain import UNKNOWN, ClassTable


@dataclass(frozen=True, eq=False)
class TerrainColumns:
    """How a class table's classes fall into the terrain columns that U and the ground map count.

    Attributes:
        of_class: terrain column of each class id (256,), as :attr:`UtilityFeaturizer.class_columns`.
        k: the number of terrain classes K (column K: ground that is none of them).
        lethal: the terrain columns of lethal classes.
        names: the classes of the K columns, for a costmap's legend.
    """

    of_class: np.ndarray
    k: int
    lethal: tuple[int, ...] = ()
    names: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if np.shape(self.of_class) != (256,) or self.k < 0 or not all(0 <= c <= self.k + 1 for c in self.lethal):
            raise ValueError("terrain columns need a column for each of the 256 class ids, K >= 0 and lethal columns up to K + 1")

    @property
    def map_columns(self) -> np.ndarray:
        """The terrain column of each class id (256,) uint8 as the ground map counts it: K + 1
        (never seen) for UNKNOWN, the pixel that sees no ground."""
        columns = np.asarray(self.of_class, dtype=np.uint8).copy()
        columns[UNKNOWN] = self.k + 1
        return columns

    @classmethod
    def of(cls, of_class: np.ndarray, k: int, classes: ClassTable, names: tuple[str, ...] = ()) -> TerrainColumns:
        """The columns ``of_class`` gives the class ids, with the columns of ``classes``' lethal classes."""
        return cls(of_class, k, tuple(sorted({int(of_class[i]) for i in classes.lethal_ids})), names)
