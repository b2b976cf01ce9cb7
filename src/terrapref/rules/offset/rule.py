"""The ``offset`` rule: choose a lateral offset from the path with a learned utility, hold it, steer to it.

Each frame the ground map (terrapref.groundmap, kept by the planner) takes in the camera's view and the offset
utility ``weights . features(d)`` (:mod:`.features`, fitted by :mod:`.fit`) scores every
candidate offset d. The rule then:

1. rules out offsets whose way there, pure pursuit toward them for ``lethal_horizon_m``, brings
   the footprint (plus ``lethal_margin_m``) onto lethal terrain, whenever any lethal terrain lies
   near the offsets' ways (the class table says which classes are lethal; that is not learned); when
   that rules out every offset, checks again with the footprint alone, without the margin, and
   keeps the offsets whose way is clear of it; when none is, those whose way runs farthest
   before lethal terrain; but first, when every way brushes the clearance, it looks beyond the
   fitted offsets on the side of the offset held (the escape offsets of step 4) for the nearest
   whose line and way keep the clearance, and holds that one while the fitted ways still brush
   it: the clearance is what absorbs the error in the robot's pose, and under the ``field``
   preset a way held inside it, the outermost fitted offset beside a lethal strip, brushed the
   strip's corner;
2. goes back to the path while nothing lies on it within the utility's near distance, unless
   the way back is ruled out (then it takes the best offset that is not);
3. otherwise keeps the offset it holds while that offset's utility falls short of the best one's
   by at most ``switch_margin`` of the best's magnitude (:func:`keeps`), and takes the best one when not, so that it does not dither between sides
   (with a ``trade_tolerance``, the one nearest the path of those nearly as good that cross no more terrain:
   :meth:`OffsetSteering.nearest_trade`);
   the vehicle faster than the control set's speed (the speed the ways are checked at), when
   lethal terrain rules out the offset held, it takes the best on the same side while that one
   falls short of the best by at most the same margin: at speed, a swap of sides costs more
   ground than the check prices, and under a robot's pose noise such swaps left it too late to
   get round;
4. but first, when lethal terrain lies across every offset the utility was fitted on at once,
   somewhere as far ahead as the offset features read (a lethal patch wider than they reach; not
   one patch beside the vehicle and another ahead on the other side, which the held offset and
   then another get round), takes the nearest offset
   beyond them on the side of the offset held, up to ``escape_factor`` times as far, that is clear
   of it, and holds it while it stays clear; the utility cannot price those offsets, so they serve
   only to get round lethal terrain;
5. steers toward the path shifted by the held offset, ``pursuit_m`` ahead.

Ground never seen is priced at the mean of the non-lethal classes' weights: a fit sees too
little unseen ground beside patches to price it, and an unknown cell is, on average, one of them.
On a map that reads depth (relief), unseen ground is mostly ground that a crest, a mound or a bank
hides from the camera, and how much a driver minds it is their own: one drives on over a mound to
see, a cautious one goes round what it cannot see past. A utility fitted on relief has seen plenty
of hidden ground, and there it prices it as its drive did, on the path's own lanes and beside
them apart (:func:`hidden_prices`, each at most 0): a mound hides ground on the path that a
driver drives into, a bank's crest ground beside it that the same driver keeps off; one
fitted on flat ground has not, and prices it as on flat ground. Priced as an average class, the
ground behind every mound on the path made a detour worth it, for a driver who drives over
mounds, as soon as anything (a mislabelled speck) lifted the gate. The stop rule still keeps the
vehicle off ground it has not seen within its stopping distance.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from terrapref.camera import PinholeCamera, SegmentationView
from terrapref.errors import UserError, finite_number
from terrapref.features import UtilityFeaturizer
from terrapref.groundmap.costmap import Costmap, costmap_of
from terrapref.groundmap.height import DepthImage
from terrapref.groundmap.map import GroundMap
from terrapref.records import to_plain
from terrapref.rules.base import (
    MOST_NUMBER,
    Choice,
    FrameReader,
    HeaderContext,
    RoutePrices,
    Rule,
    RuleConfig,
    RuleContext,
    RuleInput,
    SteeringRunner,
    TerrainColumns,
    Where,
    finite_array,
    number,
    vector,
)
from terrapref.rules.offset.features import FIRST_BAND, RELIEF_BANDS_DEG, OffsetFeatures, OffsetView
from terrapref.rules.offset.fit import HIDDEN_ON_PATH_M, OffsetFit, OffsetUtility, fit_offset_utility, relief_prices
from terrapref.rules.offset.geometry import OffsetGeometry
from terrapref.rules.offset.offsets_compiled import gated_value
from terrapref.rules.offset.reach_compiled import lethal_hits, swept_reach
from terrapref.rules.offset.steering import intent_offsets, steer
from terrapref.rules.settings import NUMBER
from terrapref.scenario.path import ReferencePath
from terrapref.terrain import ClassTable
from terrapref.vehicle import Command, ControlSet, Pose

if TYPE_CHECKING:
    from terrapref.demos.recording import Recording
    from terrapref.learning.train import FitData
    from terrapref.world import WorldMap

# The evidence a ground-map cell holds before it counts as seen, lethal or not, for a rule fitted
# on relief (a vote at 0 m weighs 1; the drive's own frames are read without it, their labels
# being true). A robot's network takes a few percent of the ground for a lethal class in blobs
# that last a few frames; a far glimpse of one made a cell lethal at once, and on relief, where
# ground comes into view late and far off past crests and mounds, such cells priced detours the
# driver never took. Waiting for about one near view's evidence (ten votes at 12 m, two at 4 m)
# lets the true labels outvote them; the stop rule keeps the vehicle off ground not yet seen
# within its stopping distance. Chosen under `field` on generated relief layouts and confirmed on
# others (docs/lab/2026-12-01-relief-evidence.md); a rule fitted on flat ground keeps the
# geometry's own (0), its decisions as they were.
RELIEF_MIN_EVIDENCE = 1.0
# The share of a cell's evidence lethal classes must hold for the cell to read as lethal, for a
# rule fitted on relief (the map's own, terrapref.groundmap.MapSettings, is 0.35). Those blobs
# of a lethal class, once near enough to count, made ground beside a patch lethal for a few
# frames: the rule ruled out the side it held, swapped across the patch to the other, and swapped
# back once the blob was outvoted, three times in two metres before one lone patch of mud. A true
# lethal patch holds nearly all its cells' evidence. Chosen under `field` on generated relief
# layouts and confirmed on others (docs/lab/2026-12-06-false-lethal-blobs.md); on flat layouts it
# gained nothing, and a rule fitted on flat ground keeps the geometry's own, its decisions as they were.
RELIEF_LETHAL_SHARE = 0.5
# A trade between classes is one the best offset's own line makes on a patch: it crosses at least
# this many metres of terrain [m]. Under `field`, misread cells put a few tenths of a metre of some
# class on most lines; taken for a trade, an offset held beside a lone patch was traded for one
# clipping it.
TRADE_LEAST_M = 1.0


@dataclass(frozen=True)
class OffsetConfig(RuleConfig):
    """How the offset rule holds and reaches an offset, and the geometry of its offsets and
    ground map (its fit reads each frame's offset features: :meth:`reader`).

    Attributes:
        switch_margin: the held offset is kept while its utility falls short of the best
            offset's by at most this share of the best's magnitude.
        pursuit_m: pure pursuit aims this far along the path ahead of the vehicle's progress [m].
        lethal_margin_m: clearance kept from lethal terrain beside the footprint [m].
        lethal_horizon_m: how far ahead the way to each offset is checked for lethal terrain [m].
        dt_s: time step of that check [s].
        escape_factor: escape offsets, used only when lethal terrain lies across every fitted
            offset as far as the features read or the way to every one brushes the clearance,
            reach this many times as far as the fitted offsets do (1 = no escape).
        trade_tolerance: when the rule takes a new offset, it takes the one nearest the path
            among those on the best one's side that cross no more terrain than it and whose
            utility falls short of the best's by at most this (the fitted utility's units: the log
            of how much less likely the fit finds the driver would hold it); 0: the best
            (:meth:`OffsetSteering.nearest_trade`). A fit keeps the config's (0 unless a robot
            sets one): where a strip lies on the path beside a better class, 0.25 kept the
            triples two of the default table's orders lost, but lost as many on the example
            table, whose fit prices the step between neighbouring classes about right
            (docs/lab/2026-12-07-edges-on-the-lattice.md).
        geometry: the candidate offsets, the stations read along the path and the ground map.
    """

    type: ClassVar[str] = "offset"
    arrays: ClassVar[dict[str, str]] = {"features": "finite >= 0", "near_m": "no NaN", "intent_m": "no inf", "relief_m": "finite >= 0"}
    without_data: ClassVar[str] = "the model gets no offset rule and drives C's trajectories"

    switch_margin: float = 0.15
    pursuit_m: float = 2.5
    lethal_margin_m: float = 0.3
    lethal_horizon_m: float = 6.0
    dt_s: float = 0.1
    escape_factor: float = 2.0
    trade_tolerance: float = 0.0
    geometry: OffsetGeometry = field(default_factory=OffsetGeometry)

    def __post_init__(self) -> None:
        values = (
            self.switch_margin,
            self.pursuit_m,
            self.lethal_margin_m,
            self.lethal_horizon_m,
            self.dt_s,
            self.escape_factor,
            self.trade_tolerance,
        )
        if (
            not all(math.isfinite(v) for v in values)
            or self.switch_margin < 0
            or self.trade_tolerance < 0
            or self.lethal_margin_m < 0
            or self.pursuit_m <= 0
            or self.lethal_horizon_m <= 0
            or self.dt_s <= 0
            or self.escape_factor < 1
        ):
            raise ValueError(
                "the offset rule needs switch_margin >= 0, trade_tolerance >= 0, lethal_margin_m >= 0, escape_factor >= 1 "
                "and positive distances and step"
            )
        if not isinstance(self.geometry, OffsetGeometry):
            raise ValueError("the offset rule's geometry must be an OffsetGeometry")

    def to_dict(self) -> dict:
        return to_plain(self)

    def summary(self) -> str:
        return "the offset rule, holding the lateral offset a utility fitted to the offsets the driver held prices best, driving"

    def data(self) -> dict[str, Any]:
        return {"geometry": self.geometry.to_dict()}

    def reader(self, featurizer: UtilityFeaturizer, camera: PinholeCamera, classes: ClassTable, n: int) -> OffsetReader:
        return OffsetReader(self.geometry, featurizer, camera, classes, n)

    def fit(self, data: FitData) -> OffsetRule | None:
        """The offset utility fitted to the offsets the driver steered for; None for data without the rule's arrays."""
        found = data.rule_config(self.type, lambda recorded: OffsetGeometry.from_dict(recorded["geometry"]))
        if found is None:
            return None
        geometry, arrays = found  # the geometry the frames were read with
        relief = arrays.get("relief_m")
        if relief is not None and relief.shape[2] != 2 * len(RELIEF_BANDS_DEG):
            raise UserError("offset rule", f"relief columns of {relief.shape[2]} bands; this version reads {2 * len(RELIEF_BANDS_DEG)}")
        columns = (relief, RELIEF_BANDS_DEG) if relief is not None else None
        fitted = fit_offset_utility(arrays["features"], arrays["near_m"], arrays["intent_m"], geometry.offsets, relief=columns)
        detour = float(fitted.weights[-2])
        if not detour < 0.0:  # every price is read against it, and a price of holding off the path below 0 steers away from it
            raise UserError(
                "offset rule",
                f"the drive did not show what holding off the path costs (its weight came out {detour:+g}, not below 0): "
                "its prices cannot be read; drive longer along a path kept, as a teaching course shows it (terrapref course)",
            )
        if relief is not None:  # a rule that drives relief waits, on the map, for the evidence of a near view, and of most of it
            geometry = replace(
                geometry,
                map_min_evidence=max(geometry.map_min_evidence, RELIEF_MIN_EVIDENCE),
                map_lethal_share=max(geometry.map_lethal_share, RELIEF_LETHAL_SHARE),
            )
        utility = OffsetUtility(
            fitted.weights, fitted.near_m, geometry, fitted.relief, fitted.relief_shown, fitted.relief_interval, fitted.hidden_on_path
        )
        return OffsetRule(replace(self, geometry=geometry), utility, fitted)


class OffsetReader(FrameReader):
    """The offset features of each frame of one recording, read in order (the ground map gathers
    them), and each frame's intended offset: the rule's training arrays.

    Arrays: ``features`` (N, O, K + 2) float32, metres per terrain class, never seen, and the
    detour's price per candidate offset; ``near_m`` (N,) float32, the distance along the path to
    the first terrain (or, on relief, steep ground) on it (inf: none within reach); ``intent_m``
    (N,) float32, the offset the driver was steering for (NaN: the recording ends before its
    reaction time has passed); and, for a drive whose frames carry depth (relief), ``relief_m``
    (N, O, 2 * len(RELIEF_BANDS_DEG)) float32, the relief columns (0 for a frame without depth)."""

    def __init__(self, geometry: OffsetGeometry, featurizer: UtilityFeaturizer, camera: PinholeCamera, classes: ClassTable, n: int) -> None:
        k = featurizer.config.n_terrain
        self.geometry = geometry
        self.map = GroundMap(camera, TerrainColumns.of(featurizer.class_columns, k, classes), geometry.map)
        self.offsets = OffsetFeatures(geometry, k)
        self.features = np.empty((n, len(self.offsets.offsets), k + 2), dtype=np.float32)
        self.near = np.empty(n, dtype=np.float32)
        self.relief: np.ndarray | None = None  # (N, O, R), from the first frame with depth
        self.progress = np.empty(n)

    def read(self, j: int, view: SegmentationView, pose: Pose, path: ReferencePath, progress_m: float) -> None:
        depth = DepthImage.of(view, self.map.camera, pose)
        self.map.update(view, pose, depth)
        frame = self.offsets(self.map, path, progress_m, relief=depth is not None)
        self.features[j], self.near[j] = frame.features, frame.near_m
        if frame.relief is not None:
            if self.relief is None:
                self.relief = np.zeros((len(self.features), *frame.relief.shape), dtype=np.float32)
            self.relief[j] = frame.relief
        self.progress[j] = progress_m

    def arrays(self, recording: Recording, keep: np.ndarray, path: ReferencePath) -> dict[str, np.ndarray]:
        """The arrays, with each frame's intended offset read from the command one reaction time later."""
        period = recording.frame_period_s
        delay = round(self.geometry.intent_delay_s / period)
        later = np.full((len(keep), 2), np.nan)
        ahead = keep + delay
        ok = ahead < len(recording)
        # Only where the frame that much later is the next ones' in time (not across a gap).
        ok[ok] &= np.abs(recording.times[ahead[ok]] - recording.times[keep[ok]] - delay * period) < 0.5 * period
        later[ok] = recording.commands[ahead[ok]]
        intent = intent_offsets(recording.poses[keep], later, self.progress, path, self.offsets.offsets, self.geometry.intent_pursuit_m)
        out = {"features": self.features, "near_m": self.near, "intent_m": intent.astype(np.float32)}
        return out if self.relief is None else {**out, "relief_m": self.relief}


@dataclass(frozen=True)
class OffsetRule(Rule):
    """A fitted offset rule: how it holds offsets, and the offset utility that prices them
    (``fit``: how the fit went, for a rule just fitted)."""

    type: ClassVar[str] = "offset"
    settable: ClassVar[dict[str, tuple[str, str]]] = {
        "switch_margin": (NUMBER, "the share of the best offset's utility the held offset may fall short by before a switch"),
        "pursuit_m": (NUMBER, "how far ahead along the path pure pursuit aims [m]"),
        "lethal_margin_m": (NUMBER, "the clearance kept from lethal terrain beside the footprint [m]"),
        "lethal_horizon_m": (NUMBER, "how far ahead the way to each offset is checked for lethal terrain [m]"),
        "trade_tolerance": (NUMBER, "how far below the best offset's utility one nearer the path, crossing no more terrain, may be taken"),
    }

    config: OffsetConfig
    utility: OffsetUtility
    fit: OffsetFit | None = None

    @classmethod
    def setting_problem(cls, name: str, value: float) -> str | None:
        """A distance of 0 or less where the rule needs one ahead, or a margin or tolerance below 0."""
        if name in ("pursuit_m", "lethal_horizon_m"):
            return "expected a distance > 0 [m]" if not value > 0 else None
        return "expected a value >= 0" if value < 0 else None

    @property
    def reads_relief(self) -> bool:
        """Whether its utility prices relief (a drive on relief taught it)."""
        return self.utility.relief is not None

    def with_settings(self, values: Mapping[str, Any], names: tuple[str, ...], lethal: frozenset[str]) -> OffsetRule:
        """The rule holding offsets as ``values`` say (its fitted utility unchanged)."""
        return replace(self, config=replace(self.config, **{k: float(v) for k, v in values.items()}))

    def header(self) -> dict[str, Any]:
        u = self.utility
        return {
            "type": self.type,
            **self.config.to_dict(),
            "weights": u.weights.tolist(),
            "near_m": u.near_m,
            **({"relief": _relief_block(u)} if u.relief is not None else {}),
            **({"loss": self.fit.loss, "samples": self.fit.samples} if self.fit is not None else {}),
        }

    @classmethod
    def from_header(cls, block: Mapping[str, Any], context: HeaderContext, where: Where) -> OffsetRule:
        raw = block.get("geometry", context.raw_features.get("corridor"))  # older files: the features' ``corridor``
        if not isinstance(raw, Mapping):
            raise where.error("geometry", "missing: an offset rule needs its geometry")
        try:
            geometry = OffsetGeometry.from_dict(dict(raw))
        except (TypeError, ValueError, KeyError, IndexError) as exc:
            raise where.error("geometry", f"invalid ({exc})") from None
        weights = vector(block, "weights", context.features.n_terrain + 3, where)
        if not weights[-2] < 0.0:  # as the fit keeps it: the cost of holding off the path
            raise where.error("weights", f"the detour's weight (the second last) must be below 0, got {weights[-2]:g}")
        near = number(block, "near_m", where, positive=True)
        if "pursuit_lookahead_m" in block and "pursuit_m" not in block:  # its name in files before it was pursuit_m
            block = {**block, "pursuit_m": block["pursuit_lookahead_m"]}
        settings = {
            f.name: number(block, f.name, where, getattr(OffsetConfig, f.name)) for f in fields(OffsetConfig) if f.name != "geometry"
        }
        try:
            config = OffsetConfig(**settings, geometry=geometry)
        except ValueError as exc:
            raise where.error("", str(exc)) from None
        relief, shown, interval = _relief_weights(block, where)
        hidden_on_path = _hidden_on_path(block, where) if relief is not None else 0.0
        fit = None
        if "loss" in block or "samples" in block:  # how the fit went, as training wrote it
            samples = block.get("samples")
            if isinstance(samples, bool) or not isinstance(samples, int) or samples < 1:
                raise where.error("samples", "expected the number of frames fitted, an integer >= 1")
            fit = OffsetFit(weights, near, number(block, "loss", where, low=0.0), {}, samples, relief, shown, interval)
        return cls(config, OffsetUtility(weights, near, geometry, relief, shown, interval, hidden_on_path), fit)

    @classmethod
    def legacy_block(cls, meta: Mapping[str, Any], source: str) -> dict[str, Any] | None:
        data = meta.get("corridor")  # files before the ``stages`` list: the utility, which drove
        if data is None:
            return None
        if not isinstance(data, dict):
            raise UserError(source, "expected a mapping", field="corridor")
        return {"type": cls.type, **data}

    def runner(self, context: RuleContext) -> OffsetSteering:
        return OffsetSteering(self.utility, context.camera, context.terrain, context.features.preference.control, self.config)

    def describe(self, names: tuple[str, ...], lethal: frozenset[str]) -> str:
        """The learned price of each class per metre, relative to the detour's per m^2 of offset per metre."""
        w = self.utility.weights
        prices = ", ".join(f"{c} {p / w[len(names) + 1]:.1f}{' (lethal: ruled out)' if c in lethal else ''}" for c, p in zip(names, w))
        fitted = f"fitted to {self.fit.samples} frames, " if self.fit is not None else ""
        text = (
            f"offset rule: {fitted}near distance {self.utility.near_m:g} m; each class's price per metre, "
            f"relative to the detour's per m^2 of offset per metre: {prices}"
        )
        return "\n  ".join([text, *self.relief_lines()])  # under the first line, as train and info indent it

    def relief_lines(self) -> list[str]:
        """The relief the utility prices, a line for side slope and one for grade: a metre's price
        past each band, on the classes' scale, and the bands past the steepest ground its drive
        showed; the price of ground not yet seen, and the evidence its map waits for; none for a
        utility that prices no relief."""
        u = self.utility
        if u.relief is None:
            return []
        w, bands = u.weights, len(RELIEF_BANDS_DEG)
        detour = w[len(w) - 2]
        lines = []
        prices = relief_prices(u.relief, detour)  # a metre's price past each band: the band's and those below it
        for k, what in enumerate(("side slope", "grade")):
            shown = ", ".join(
                f"{b:g} {prices[k * bands + j] + 0.0:.1f}" + _interval(u.relief_interval, k * bands + j)
                for j, b in enumerate(RELIEF_BANDS_DEG)
            )
            steepest = (u.relief_shown or (math.nan, math.nan))[k]
            told = (
                "the drive showed none past the first band: it cannot tell these prices"
                if math.isnan(steepest)
                else f"the drive showed none past {steepest:g} deg: steeper is priced as that band"
                if steepest < RELIEF_BANDS_DEG[-1]
                else "the drive showed every band"
            )
            lines.append(
                f"relief, the body heading along the path: {what} past each band [deg] (its price per metre, as the classes'"
                f"{', with its 95% interval; held: no spread, held at 0 or past no ground the drive showed' if u.relief_interval is not None else ''}): "
                f"{shown}; {told}"
            )
        hidden = hidden_prices(u)
        if detour != 0.0 and hidden is not None:
            beside, on_path = (p / detour + 0.0 for p in hidden)
            lines.append(
                f"relief, ground not yet seen (behind a crest, a mound, a bank): {beside:.1f} per metre beside the path, "
                f"{on_path:.1f} on its own lanes (within {HIDDEN_ON_PATH_M:g} m of it), as the classes' "
                "(ground the camera has not shown, on a map that reads depth)"
            )
        g = self.config.geometry
        if g.map_min_evidence > 0.0:  # a vote at r metres weighs 1 / (1 + (r / map_range_m)^2) (terrapref.groundmap.map)
            far, near = (math.ceil(g.map_min_evidence * (1.0 + (r / g.map_range_m) ** 2) - 1e-9) for r in (12.0, 4.0))
            lines.append(
                f"map: a cell counts as seen, lethal or not, once it holds {g.map_min_evidence:g} of evidence "
                f"(a vote at 0 m weighs 1: {far} votes at 12 m, {near} at 4 m), and reads as lethal once lethal classes "
                f"hold {g.map_lethal_share:.0%} of it"
            )
        return lines


def _interval(interval: np.ndarray | None, k: int) -> str:
    """`` (low to high)`` of a relief price's 95% interval, `` held`` where it has no spread (its
    bands held at 0 by the fit, or past no ground the drive showed: its price is not told), or
    nothing where it is not known."""
    if interval is None:
        return ""
    low, high = interval[k]
    return " held" if low == high else f" ({low + 0.0:.1f} to {high + 0.0:.1f})"


def _relief_block(utility: OffsetUtility) -> dict[str, Any]:
    """The ``relief`` mapping of a rule's block: the bands, a weight per column, the steepest band
    of each the drive showed (null: none) and, where known, each price's 95% interval."""
    shown = [None if math.isnan(v) else v for v in utility.relief_shown or (math.nan, math.nan)]
    block = {"bands_deg": list(RELIEF_BANDS_DEG), "weights": utility.relief.tolist(), "shown_deg": shown}
    if utility.relief_interval is not None:
        block["price_interval"] = utility.relief_interval.tolist()
    block["hidden_on_path"] = float(utility.hidden_on_path)
    return block


def _relief_weights(block: Mapping[str, Any], where: Where) -> tuple[np.ndarray | None, tuple[float, float] | None, np.ndarray | None]:
    """The relief columns' weights of a rule's block (its ``relief`` mapping, :func:`_relief_block`),
    the steepest bands its drive showed and the prices' intervals (None: a file written before
    them), or None, None, None where it has none (a utility fitted on flat ground)."""
    relief = block.get("relief")
    if relief is None:
        return None, None, None
    if not isinstance(relief, Mapping) or not {"bands_deg", "weights", "shown_deg"} <= set(relief) <= {
        "bands_deg",
        "weights",
        "shown_deg",
        "price_interval",
        "hidden_on_path",
    }:
        raise where.error("relief", "expected a mapping of bands_deg, weights, shown_deg and optionally price_interval and hidden_on_path")
    shown = relief["shown_deg"]
    if not (isinstance(shown, list) and len(shown) == 2 and all(v is None or v in RELIEF_BANDS_DEG for v in shown)):
        raise where.error("relief.shown_deg", "expected two of the bands (side slope, grade), each or null")
    if relief["bands_deg"] != list(RELIEF_BANDS_DEG):
        raise where.error("relief.bands_deg", f"expected the bands this version reads, {list(RELIEF_BANDS_DEG)}")
    weights = finite_array(relief["weights"], (2 * len(RELIEF_BANDS_DEG),))
    if weights is None or (weights > 0.0).any():  # each band adds a price, as the fit keeps them (steeper never costs less)
        raise where.error(
            "relief.weights", f"expected {2 * len(RELIEF_BANDS_DEG)} finite numbers, each at most 0 and within -{MOST_NUMBER:g}"
        )
    roll, grade = (math.nan if v is None else float(v) for v in shown)
    interval = None
    if "price_interval" in relief:
        interval = finite_array(relief["price_interval"], (len(weights), 2))
        if interval is None or (interval[:, 0] > interval[:, 1]).any() or (interval < 0).any():  # a price is never below 0
            raise where.error("relief.price_interval", f"expected {len(weights)} pairs of finite numbers >= 0, low then high")
    return weights, (roll, grade), interval


def _hidden_on_path(block: Mapping[str, Any], where: Where) -> float:
    """The relief block's ``hidden_on_path`` (0 in a file written before it was fitted)."""
    value = block["relief"].get("hidden_on_path", 0.0)
    if not (finite_number(value) and abs(value) <= MOST_NUMBER):
        raise where.error("relief.hidden_on_path", f"expected a finite number within +-{MOST_NUMBER:g}")
    return float(value)


def steep_from(utility: OffsetUtility) -> tuple[float, float]:
    """The side slope and grade [deg] past which ground on the path is a patch on it for
    ``utility``: the first band of each it prices (inf: none)."""
    if utility.relief is None:
        return FIRST_BAND
    half = len(RELIEF_BANDS_DEG)
    first = [np.flatnonzero(weights) for weights in (utility.relief[:half], utility.relief[half:])]
    return tuple(float(RELIEF_BANDS_DEG[f[0]]) if len(f) else math.inf for f in first)


def hidden_prices(utility: OffsetUtility) -> tuple[float, float] | None:
    """The weights of a metre of ground never seen on a map that reads depth, beside the path and
    on its own lanes (the offsets within :data:`HIDDEN_ON_PATH_M` of it), as a utility fitted on
    relief weighs them, each at most 0; None for one fitted on flat ground (:func:`hidden_price`)."""
    beside = hidden_price(utility)
    if beside is None:
        return None
    return beside, min(float(utility.weights[len(utility.weights) - 3]) + float(utility.hidden_on_path), 0.0)


def hidden_price(utility: OffsetUtility) -> float | None:
    """The weight of a metre of ground never seen on a map that reads depth (module docstring): as
    a utility fitted on relief weighs it, at most 0 (ground not seen is no reason to drive there);
    None for one fitted on flat ground, whose drive showed too little of it to tell (it is priced
    as on flat ground)."""
    if utility.relief is None:
        return None
    return min(float(utility.weights[len(utility.weights) - 3]), 0.0)


def keeps(held: float, best: float, margin: float) -> bool:
    """Whether an offset whose utility is ``held`` is kept against the best one's, ``best``: it is
    while it falls short of the best by at most ``margin`` of the best's magnitude (a learned
    utility may be positive or negative; a margin of the best value itself would be none at all
    where the best is positive)."""
    return held >= best - margin * abs(best)


class OffsetSteering(SteeringRunner):
    """The offset rule (module docstring) of one camera, class table and offset utility.

    Args:
        utility: the fitted offset utility.
        camera: the robot's camera.
        terrain: the class table's terrain columns (which are lethal; the costmap's names).
        control: the control set (the forward speed, and the trajectories a yaw rate is named by).
        config: how offsets are held and reached.
    """

    def __init__(
        self,
        utility: OffsetUtility,
        camera: PinholeCamera,
        terrain: TerrainColumns,
        control: ControlSet,
        config: OffsetConfig | None = None,
    ) -> None:
        k = terrain.k
        if utility.weights.shape != (k + 3,):
            raise ValueError(f"the offset utility has {utility.weights.shape[0]} weights, expected {k + 3}")
        self.utility, self.config, self.k = utility, config or OffsetConfig(), k
        self.half_width_m = float(utility.config.half_width_m)
        self.control, self.v_mps, self.names = control, float(control.v_mps), terrain.names
        self.lethal = np.zeros(k + 2, dtype=bool)
        self.lethal[np.asarray(terrain.lethal, dtype=np.int64)] = True
        weights = np.array(utility.weights, dtype=float)
        safe = [j for j in range(k) if not self.lethal[j]]
        if safe:
            weights[k] = weights[safe].mean()
        self.weights = weights
        self._weights_on_relief = weights.copy()  # on a map that reads depth: unseen ground priced as a relief drive did
        hidden = hidden_price(utility)
        if hidden is not None:
            self._weights_on_relief[k] = hidden
        # Ground never seen on the path's own lanes, priced apart from beside them (hidden_prices).
        self._on_path = (np.abs(utility.config.offsets) <= HIDDEN_ON_PATH_M + 1e-9).astype(float)
        prices = hidden_prices(utility)
        self._on_path_extra = 0.0 if prices is None else prices[1] - prices[0]
        self.map_settings = utility.config.map
        self._columns = terrain.map_columns  # a prior map's class ids as the ground map's columns
        self.features = OffsetFeatures(utility.config, k)
        self.offsets = self.features.offsets
        m = utility.config.half_width_m + self.config.lethal_margin_m
        self._clear = np.linspace(-m, m, 7)  # the footprint and its clearance, across [m]
        self._bare = np.linspace(-utility.config.half_width_m, utility.config.half_width_m, 5)  # the footprint alone [m]
        self._line_stations = np.arange(-0.5, self.config.lethal_horizon_m + 1e-9, 0.25)
        self._far_stations = np.arange(-0.5, utility.config.stations_m[1] + 1e-9, 0.25)
        self._steps = round(self.config.lethal_horizon_m / (self.v_mps * self.config.dt_s))
        reach, step = utility.config.max_offset_m, utility.config.offset_step_m
        beyond = np.arange(reach + step, reach * self.config.escape_factor + 1e-9, step)
        self.escapes = np.concatenate([-beyond[::-1], beyond])  # (E,) offsets only for getting round lethal terrain [m]
        self._outermost = self.offsets[[0, -1]]
        self._centre = int(np.argmin(np.abs(self.offsets)))
        self.steep_deg = steep_from(utility)
        self.held = 0.0

    reads_probs = False

    def reset(self) -> None:
        """Start a new run: forget the held offset."""
        self.held = 0.0

    def decide(self, frame: RuleInput) -> Choice:
        """Steered continuously within the control set's range of yaw rates; the index names the nearest trajectory."""
        if frame.ground_map is None:
            raise ValueError("the offset rule reads a ground map: the frame has none")
        w = float(
            np.clip(
                self.yaw_rate(frame.ground_map, frame.pose, frame.path, frame.progress_m, frame.speed_mps),
                self.control.w_rps[0],
                self.control.w_rps[-1],
            )
        )
        return Choice(int(self.control.label_of(w)), Command(self.control.v_mps, w), float(self.held))

    def yaw_rate(self, gmap: GroundMap, pose: Pose, path: ReferencePath, progress_m: float, speed_mps: float | None = None) -> float:
        """The yaw rate [rad/s] toward the offset held after this frame, read from ``gmap`` (the
        ground map of :attr:`map_settings`, updated with the frame), the vehicle going at
        ``speed_mps`` [m/s] (None: the control set's speed)."""
        seen = self.features(gmap, path, progress_m, relief=self.utility.relief is not None, steep_deg=self.steep_deg)
        weights = self._weights_on_relief if gmap.reads_depth else self.weights
        value = gated_value(seen.features, self.offsets, seen.near_m > self.utility.near_m, weights)
        if seen.relief is not None:
            value = value + seen.relief @ self.utility.relief
            if gmap.reads_depth and self._on_path_extra != 0.0:
                value = value + seen.features[:, self.k] * (self._on_path_extra * self._on_path)
        escape = None
        if self.lethal[: self.k].any():
            lines = None  # the offsets' lines to the horizon, when the far read below already holds them
            if self._lines(gmap, self._outermost, path, progress_m, self._far_stations).all():  # the outermost two first: cheaper
                far = self._hits(gmap, self.offsets, path, progress_m, self._far_stations)
                if far.all(axis=0).any():  # across every offset at once: not two patches, one beside and one ahead
                    escape = self._escape(gmap, value, path, progress_m)
                if len(self._line_stations) <= far.shape[1]:
                    lines = far[:, : len(self._line_stations)].any(axis=1)  # the same stations, from the same start and step
            blocked, brushed = self._ruled_out(gmap, self.offsets, pose, path, progress_m, lines)
            if not blocked.all():
                value = np.where(blocked, -np.inf, value)
            if escape is None and brushed:
                escape = self._wider(gmap, value, pose, path, progress_m)
        best = int(np.argmax(value))
        held = int(np.argmin(np.abs(self.offsets - self.held)))
        if escape is not None:
            self.held = escape
        elif seen.near_m > self.utility.near_m and np.isfinite(value[self._centre]):
            self.held = 0.0  # nothing near and the way back clear of lethal terrain
        elif self.held == 0.0 or abs(self.held) > self.offsets[-1] or not keeps(value[held], value[best], self.config.switch_margin):
            fast = speed_mps is not None and speed_mps > self.v_mps
            new = self._same_side(value, best) if fast and not np.isfinite(value[held]) else self.nearest_trade(value, best, seen)
            self.held = float(self.offsets[new])
        return float(steer(path, pose, progress_m, self.held, self.config.pursuit_m, self.v_mps))

    def route_prices(self) -> RoutePrices:
        """The class prices and the price of holding off the path this rule learned (``-w_detour``), for a route search."""
        return RoutePrices(self._prior, float(-self.utility.weights[self.k + 1]), float(self.utility.config.span_m))

    def _prior(self, world: WorldMap) -> Costmap:
        """The costmap of a prior map ``world`` (every cell known), priced as the ground map's cells are."""
        cells = self._columns[world.raster]
        return costmap_of(cells, np.zeros(2), world.resolution_m, self.utility.weights, self.lethal, self.names)

    def costmap(self, ground_map: GroundMap) -> Costmap:
        """``ground_map`` (of :attr:`map_settings`) priced by the learned utility (terrapref.groundmap.costmap)."""
        return costmap_of(
            ground_map.cells, ground_map.origin, ground_map.settings.map_resolution_m, self.utility.weights, self.lethal, self.names
        )

    def nearest_trade(self, value: np.ndarray, best: int, seen: OffsetView) -> int:
        """The offset to take for the ``best`` one (step 3 of the module docstring): of the offsets
        between the path and it, on its side, that cross no more metres of terrain (``seen``'s
        class columns summed), nor of relief past any band, and whose utility falls short of the
        best's by at most ``trade_tolerance``, the one nearest the path; the best itself where its
        line crosses less than :data:`TRADE_LEAST_M` of terrain (no trade between classes).

        Between two classes (a strip of one on the path, a better one beside it) a driver moves
        out as far as the better class is worth its detour, and a fitted utility that is nearly
        flat over the offsets in between cannot say how far that is; where moving in would cross
        more terrain (a patch gone round), there is no such trade."""
        tolerance = self.config.trade_tolerance
        if tolerance <= 0.0 or self.offsets[best] == 0.0 or not np.isfinite(value[best]):
            return best
        metres = seen.features[:, : self.k].sum(axis=1)
        if metres[best] < TRADE_LEAST_M:
            return best
        between = (np.sign(self.offsets) != -np.sign(self.offsets[best])) & (np.abs(self.offsets) <= abs(self.offsets[best]))
        near = between & (value >= value[best] - tolerance) & (metres <= metres[best] + 1e-6)
        if seen.relief is not None:  # nor steeper ground: a mound on the path is not traded for
            near &= (seen.relief <= seen.relief[best] + 1e-6).all(axis=1)
        return int(np.flatnonzero(near)[np.argmin(np.abs(self.offsets[near]))])

    def _same_side(self, value: np.ndarray, best: int) -> int:
        """The offset to take when lethal terrain rules out the one held, the vehicle faster than the
        speed the ways are checked at (step 3 of the module docstring): the best on the held offset's
        side while it falls short of ``best`` by at most the switch margin, else ``best``."""
        side = (np.sign(self.offsets) == np.sign(self.held)) & np.isfinite(value)
        if not side.any():
            return best
        kept = int(np.flatnonzero(side)[np.argmax(value[side])])
        return kept if keeps(value[kept], value[best], self.config.switch_margin) else best

    def _escape(self, gmap: GroundMap, value: np.ndarray, path: ReferencePath, progress_m: float) -> float | None:
        """The escape offset to hold when lethal terrain lies across every fitted offset, or None
        if none is clear as far as the offset features read. The one held is kept while clear; otherwise
        the nearest clear one on the side of the offset held (a swap of sides while going round
        heads across the patch: under a robot's pose noise one such swap, 2.5 m before a lone
        tree at 1.5 m/s, brushed it), and of two as near, the one on the side whose outermost fitted
        offset the utility prefers; none clear on that side, the nearest on the other. Holding
        none, the nearest on either side."""
        if self.escapes.size == 0:
            return None
        clear = ~self._lines(gmap, self.escapes, path, progress_m, self._far_stations)
        if not clear.any():
            return None
        if abs(self.held) > self.offsets[-1] and clear[np.argmin(np.abs(self.escapes - self.held))]:
            return self.held
        side = np.where(self.escapes > 0, value[-1], value[0])
        across = np.sign(self.escapes) != np.sign(self.held) if self.held != 0.0 else np.zeros(len(self.escapes), dtype=bool)
        order = np.lexsort((-side, np.abs(self.escapes), across))  # the held side, nearest, then the preferred side
        return float(self.escapes[order[np.argmax(clear[order])]])

    def _wider(self, gmap: GroundMap, value: np.ndarray, pose: Pose, path: ReferencePath, progress_m: float) -> float | None:
        """The escape offset to hold when the way to every fitted offset brushes the clearance
        (step 1 of the module docstring): the nearest, on the side of the offset held (holding
        none, of the best offset ``value`` leaves), whose line and way keep the clearance; None
        where none does."""
        side = np.sign(self.held if self.held != 0.0 else self.offsets[int(np.argmax(value))])
        wider = self.escapes[np.sign(self.escapes) == side]
        if wider.size == 0:
            return None
        wider = wider[np.argsort(np.abs(wider))]
        keep = ~self._lines(gmap, wider, path, progress_m, self._line_stations)
        keep[keep] = self._swept(gmap, wider[keep], pose, path, progress_m) == self._steps
        return float(wider[np.argmax(keep)]) if keep.any() else None

    def _ruled_out(
        self, gmap: GroundMap, offsets: np.ndarray, pose: Pose, path: ReferencePath, progress_m: float, lines: np.ndarray | None = None
    ) -> tuple[np.ndarray, bool]:
        """Which of ``offsets`` (O,) lethal terrain rules out (on ``gmap``), and whether the way to
        every one of them brushes the clearance.

        First each offset's line parallel to the path, from 0.5 m behind to the horizon, with the
        footprint and its clearance (``lines``, when already read). Where some line meets lethal
        terrain, the way to every offset is followed too, and offsets whose way there meets it
        are also ruled out. When that would rule out all of them (beside lethal terrain, every
        way brushes its clearance), the lines and ways are checked again with the footprint
        alone, and those clear of it stay: a side that only the margin rules out is kept rather
        than traded, on which way brushes the margin a step later (noise decides that), for a
        way across the lethal patch. When even the footprint meets lethal terrain on every way
        (lethal terrain, seen or misread, lies across them all), those whose way runs farthest
        before it stay, on the side of the offset held if it holds one: which way runs farthest
        changes with each step of pose noise, and a swap of sides then heads across the patch.
        Of those that stay, the ones whose line is clear with the margin, if any is.
        """
        if lines is None:
            lines = self._lines(gmap, offsets, path, progress_m, self._line_stations)
        if not lines.any():
            return lines, False
        reach = self._swept(gmap, offsets, pose, path, progress_m)
        both = lines | (reach < self._steps)
        if not both.all():
            return both, False
        reach = self._swept(gmap, offsets, pose, path, progress_m, self._bare)
        keep = ~self._lines(gmap, offsets, path, progress_m, self._line_stations, self._bare) & (reach == self._steps)
        if not keep.any():
            side = np.sign(offsets) == np.sign(self.held) if self.held != 0.0 else np.ones(len(offsets), bool)
            side = side if side.any() else np.ones(len(offsets), bool)
            keep = side & (reach == reach[side].max())
        return ~(keep & ~lines if (keep & ~lines).any() else keep), True

    def _lines(
        self,
        gmap: GroundMap,
        offsets: np.ndarray,
        path: ReferencePath,
        progress_m: float,
        stations: np.ndarray,
        across: np.ndarray | None = None,
    ) -> np.ndarray:
        """Which of ``offsets`` (O,) have lethal terrain on their line parallel to the path, at
        ``stations`` (S,) from the vehicle's progress, across the footprint and its clearance
        (``across``, by default)."""
        return self._hits(gmap, offsets, path, progress_m, stations, across).any(axis=1)

    def _hits(
        self,
        gmap: GroundMap,
        offsets: np.ndarray,
        path: ReferencePath,
        progress_m: float,
        stations: np.ndarray,
        across: np.ndarray | None = None,
    ) -> np.ndarray:
        """:meth:`_lines` station by station, (O, S); ``across`` the points across each line (the
        footprint and its clearance by default)."""
        across = self._clear if across is None else across
        if gmap.origin is None:
            return np.broadcast_to(self.lethal[self.k + 1], (len(offsets), len(stations))).copy()
        a, d, length = path.segments
        return lethal_hits(
            gmap.layers(),
            path.s,
            a,
            d,
            length,
            float(progress_m),
            stations,
            np.asarray(offsets, dtype=np.float64),
            across,
            self.lethal,
            self.k + 1,
        )

    def _swept(
        self, gmap: GroundMap, offsets: np.ndarray, pose: Pose, path: ReferencePath, progress_m: float, across: np.ndarray | None = None
    ) -> np.ndarray:
        """For each of ``offsets`` (O,), the step of ``dt_s`` at which pure pursuit toward it first drives
        the footprint (``across``, with its clearance by default) onto lethal terrain, ``self._steps``
        where it does not within the horizon."""
        across = self._clear if across is None else across
        c = self.config
        a, d, length = path.segments
        return swept_reach(
            float(pose[0]),
            float(pose[1]),
            float(pose[2]),
            offsets,
            float(progress_m),
            self.v_mps,
            c.dt_s,
            self._steps,
            c.pursuit_m,
            path.s,
            a,
            d,
            length,
            across,
            gmap.layers(),
            self.lethal,
            self.k + 1,
        )
