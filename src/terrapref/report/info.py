"""`terrapref info FILE`: what a recording, dataset, model or exported ONNX model holds, read from
its metadata alone (no tensor is used, no code from the file is run)."""

from __future__ import annotations

from pathlib import Path

from terrapref.errors import UserError
from terrapref.learning.header import CHECKPOINT, CLASSIFIER, INTERRUPTED


def _camera(c: dict) -> str:
    intr = f"fx {c['fx']:.1f}" if c.get("fx") is not None else f"{c.get('hfov_deg')} deg field of view"
    return (
        f"{c.get('width_px')}x{c.get('height_px')}, {intr}, {c.get('mount_height_m')} m high, "
        f"pitched {c.get('pitch_deg')} deg, {c.get('max_range_m')} m range"
    )


def _preference(p: dict) -> str:
    control = p.get("control", {})
    w = control.get("w_rps", [])
    return f"{len(w)} trajectories at {control.get('v_mps')} m/s, w {min(w, default=0):g}..{max(w, default=0):g} rad/s, n {p.get('n_steps')}, dt {p.get('dt_s')} s"


def _common(meta: dict) -> list[str]:
    out = []
    if isinstance(meta.get("camera"), dict):
        out.append(f"camera          {_camera(meta['camera'])}")
    features = meta.get("features")
    pref = features.get("preference") if isinstance(features, dict) else meta.get("preference_set")
    if isinstance(pref, dict):
        out.append(f"preference set  {_preference(pref)}")
    if _named_order(meta.get("profile")):
        out.append(f"profile         {' > '.join(meta['profile'])}")
    elif meta.get("profile") is not None:
        out.append("profile         (unreadable)")
    elif isinstance(meta.get("classes"), dict):  # a file of driven frames that names no order: its drives declared none
        out.append("profile         none declared")
    classes = meta.get("classes")
    if isinstance(classes, dict) and isinstance(classes.get("classes"), list):
        out.append(f"classes         {', '.join(str(c.get('name')) for c in classes['classes'])} (background {classes.get('background')})")
    return out


def _identifiability(meta: dict) -> list[str]:
    data = meta.get("identifiability")
    if not isinstance(data, dict):
        return []
    from terrapref.learning.identify import Identifiability

    try:
        report = Identifiability.from_dict(data)
    except (KeyError, TypeError, ValueError):
        return ["identifiability (unreadable)"]
    profile = meta.get("profile") if _named_order(meta.get("profile")) else None  # a damaged file's is shown only if it reads
    return ["what the demonstrations show:"] + [f"  {line}" for line in report.lines_with_order(profile)]


def _named_order(value: object) -> bool:
    """Whether ``value`` reads as an order of classes: a list of distinct names."""
    return isinstance(value, list) and all(isinstance(n, str) for n in value) and len(set(value)) == len(value)


class NotReadable(UserError):
    """A model file the reader refuses, which ``info`` still shows as far as its header can be
    read: ``shown`` holds those lines, the problems why it is refused."""

    def __init__(self, refused: UserError, shown: list[str]) -> None:
        super().__init__(refused.source, refused.problems)
        self.shown = shown

    def __reduce__(self) -> tuple:
        # Rebuilt from its own arguments, as UserError is (its signature differs).
        return (type(self), (UserError(self.source, self.problems), self.shown))


def info_lines(path: str | Path) -> list[str]:
    """A summary of ``path`` for people; every problem is a UserError naming the file (a model
    file the reader refuses: :class:`NotReadable`, with what its header still shows)."""
    p = Path(path)
    if p.is_dir():
        return _recording_lines(p)
    if p.suffix == ".onnx":
        return _onnx_lines(p)
    meta, shapes = _tensor_file_header(p)
    fmt = meta.get("format")
    from terrapref.dataset import FORMAT as DATASET
    from terrapref.dataset import OLD_FORMATS
    from terrapref.learning.header import FORMAT as MODEL

    if fmt == DATASET:
        return _dataset_lines(p, meta, shapes)
    if fmt in OLD_FORMATS:
        raise UserError(str(p), f"a dataset of an earlier version ({fmt}); featurize its recordings again", field="format")
    if fmt == MODEL:
        return _model_lines(p, meta)
    raise UserError(str(p), f"format {fmt!r} is not a terrapref recording, dataset or model", field="format")


def _recording_lines(p: Path) -> list[str]:
    """A recording folder: completeness, frames, course, driver."""
    from terrapref.demos.meta import ImportedInfo
    from terrapref.demos.recording import read_recording

    rec = read_recording(p)
    m = rec.meta
    driver = rec.header.driver
    lines = [
        f"{p}: terrapref recording ({'complete' if rec.complete else 'partial'})",
        f"frames          {len(rec)} ({rec.duration_s:.1f} s)",
        f"scenario        {m.get('scenario')}",
        f"driver          {driver.describe() if driver is not None else '?'}",
        f"perception      {_perception(rec.perception, imported=isinstance(driver, ImportedInfo))}",
        f"created         {m.get('created', '?')}",
    ]
    return lines + _common(m)


def _perception(name: str, imported: bool = False) -> str:
    """The perception model a recording's frames went through, said in words; an ``imported`` log's
    frames are what the robot's own segmentation and localisation gave."""
    if imported:
        return "the robot's own (the log's label images and odometry, as imported)"
    if name == "clean":
        return "clean (the simulator's own labels and poses)"
    return f"{name} (what the robot's camera and localisation would have given; the driver saw the truth)"


def _onnx_lines(p: Path) -> list[str]:
    """An exported ONNX model, from the terrapref metadata stored in it."""
    from terrapref.interop.onnx_export import read_onnx_metadata

    try:
        meta = read_onnx_metadata(p)
    except Exception as exc:  # onnx's parser raises several kinds on a foreign or damaged file
        raise UserError(str(p), f"not an ONNX model terrapref can read ({type(exc).__name__})") from None
    c = meta.get("classifier", {})
    return (
        [
            f"{p}: C exported as ONNX ({meta.get('format', 'no terrapref metadata')})",
            f"network         {c.get('members', 1)} member(s), hidden {c.get('hidden')}, {c.get('activation')}, skip {c.get('skip')}",
            *_rule_lines(meta, str(p), graph_note=True),
        ]
        + _common(meta)
        + _identifiability(meta)
    )


def _rule_lines(meta: dict, source: str, graph_note: bool = False) -> list[str]:
    """The rules a file's metadata lists (a model's header, an exported graph's metadata), read
    by the rules themselves (terrapref.rules.rules_in); a damaged list is said to be one.
    ``graph_note``: an exported graph, which holds C alone."""
    from terrapref.rules import rules_in
    from terrapref.terrain import ClassTable

    try:
        rules, driving = rules_in(meta, source)
        classes = ClassTable.from_dict(meta["classes"], source)
    except (UserError, KeyError, TypeError, ValueError) as exc:
        return [f"rules           unreadable ({exc.problems[0].format('') if isinstance(exc, UserError) else exc})"]
    return _rules(rules, driving, tuple(meta["features"].get("feature_classes", ())), classes, graph_note)


def _rules(rules, driving, names: tuple[str, ...], classes, graph_note: bool = False) -> list[str]:
    """The rule that drives and the rules fitted only to be reported, each as it describes itself."""
    from terrapref.rules.base import SPEED, STEERING

    lethal = frozenset({classes.lethal_column} if classes.lethal else ())  # the terrain column the lethal classes share
    note = " (in the metadata; the graph holds C alone)" if graph_note and not driving.graph else ""
    speed = next((r.type for r in rules if r.kind == SPEED), "none (the control set's speed)")
    lines = [f"steers          {driving.type}{note}", f"sets the speed  {speed}"]
    for rule in rules:
        lines.append(
            f"  {rule.describe(names, lethal)}"
            + ("" if rule is driving or rule.kind != STEERING else " (fitted to be reported; it does not steer)")
        )
        lines += [f"  warning: {warning}" for warning in rule.warnings(names, lethal)]
    return lines


def _tensor_file_header(p: Path) -> tuple[dict, dict[str, tuple[int, ...]]]:
    """The terrapref metadata of a safetensors file and the shape of each tensor (none is read)."""
    from terrapref.tensorfile import META_KEY, damage, parse_metadata

    if not p.is_file():
        raise UserError(str(p), "no such file or recording folder")
    from safetensors import SafetensorError, safe_open

    try:
        with safe_open(str(p), framework="numpy") as fh:
            header = fh.metadata() or {}
            shapes = {k: tuple(fh.get_slice(k).get_shape()) for k in fh.keys()}
    except (SafetensorError, OSError, ValueError):
        raise UserError(str(p), damage(p) or "not a terrapref recording, dataset, model or ONNX file") from None
    if META_KEY not in header:
        raise UserError(str(p), "not a terrapref recording, dataset, model or ONNX file (no terrapref metadata)")
    meta = parse_metadata(header[META_KEY], str(p))
    if not isinstance(meta, dict):
        raise UserError(str(p), "metadata is not a mapping", field="metadata")
    return meta, shapes


def _dataset_lines(p: Path, meta: dict, shapes: dict[str, tuple[int, ...]]) -> list[str]:
    """A dataset: samples, the decision rules whose data it holds, and the recordings it came from."""
    n = shapes.get("U", (0,))[0]
    recs = meta.get("recordings", [])
    rules = meta.get("rules") if isinstance(meta.get("rules"), dict) else {}
    return (
        [
            f"{p}: terrapref dataset",
            f"samples         {n} from {len(recs)} recording(s)",
            f"rules' data     {', '.join(rules) or 'none (C alone)'}",
        ]
        + [
            f"  {r.get('path')}: {r.get('frames')} frames, {r.get('scenario')}"
            + (f", perception {r['perception']}" if r.get("perception", "clean") != "clean" else "")
            for r in recs
            if isinstance(r, dict)
        ]
        + _common(meta)
    )


def _model_lines(p: Path, meta: dict) -> list[str]:
    """A model: its state, recipe, network, decision rules, training data and chosen epoch, as
    terrapref.planner.model.Model reads the file; a file it refuses is :class:`NotReadable`,
    shown as far as its header can be read, with the refusal."""
    from terrapref.errors import UserError
    from terrapref.planner.model import Model

    try:
        model = Model.load(p)
    except UserError as exc:
        raise NotReadable(exc, _damaged_model_lines(p, meta, exc)) from None
    loaded = model.classifier
    if loaded is None:  # a learned baseline: its kind and configuration
        return [f"{p}: terrapref model ({model.kind})"] + _common(meta)
    h = loaded.header
    c, data = h.classifier, h.data
    state = {INTERRUPTED: ", INTERRUPTED: the best epochs so far, no decision rules", CHECKPOINT: f", checkpoint of epoch {h.epoch}"}
    runs = [(m.history, m.best_epoch) for m in h.members] if h.members else [(h.history, h.best_epoch)]
    chosen = [
        _epoch_line(len(history), best, history[best - 1].val_loss, history[best - 1].val_acc) if _chosen(history, best) else None
        for history, best in runs
    ]
    return (
        [
            f"{p}: terrapref model ({model.kind}{state.get(h.status, '')})",
            f"recipe          {h.recipe or '?'}",
            f"network         {c.members} member(s), hidden {c.hidden}, {c.activation}, skip {c.skip}",
            *_rules(model.rules, model.driving, h.features.feature_classes, h.classes),
            *_limit_lines(model),
            "data            "
            + (
                f"{data.samples} samples, fingerprint {data.fingerprint}, {len(data.recordings)} recording(s)"
                if data
                else "? (none recorded)"
            ),
        ]
        + _training_lines(chosen, bool(h.members))
        + _common(meta)
        + _identifiability(meta)
    )


def _limit_lines(model) -> list[str]:
    """A flag where the model's speed rule goes faster than the default vehicle's top speed: a robot holds it to its own."""
    from terrapref.vehicle import VehicleConfig

    top, limit = model.top_speed_mps, VehicleConfig().max_speed_mps
    if top is None or top <= limit:
        return []
    return [
        f"  WARNING: its speed rule goes up to {top:g} m/s, above the default vehicle's {limit:g} m/s; a robot holds it to its own top speed"
    ]


def _chosen(history, best) -> bool:
    """Whether ``best`` is an epoch of ``history`` (from 1)."""
    return isinstance(history, (list, tuple)) and isinstance(best, int) and 0 < best <= len(history)


def _epoch_line(epochs: int, best: int, val_loss: float, val_acc: float) -> str:
    """Epochs run, the epoch chosen and its validation scores, as one line."""
    return f"{epochs} epochs, chose epoch {best}: val loss {val_loss:.4f}, val acc {val_acc:.3f}"


def _training_lines(chosen: list[str | None], members: bool) -> list[str]:
    """The ``training`` lines: the run's chosen epoch, or each ensemble member's (``members``);
    None where the history does not record it."""
    lines = [f"member {j + 1}: {line}" if members else line for j, line in enumerate(chosen) if line]
    return [("training        " if i == 0 else " " * 16) + line for i, line in enumerate(lines)]


def _damaged_model_lines(p: Path, meta: dict, exc) -> list[str]:
    """A model file the reader refuses: what its header still says, and why it is refused."""
    c = meta.get("classifier", {}) if isinstance(meta.get("classifier"), dict) else {}
    lines = [
        f"{p}: terrapref model ({meta.get('kind', CLASSIFIER)}), NOT READABLE: {exc.problems[0].format('')}",
        f"recipe          {meta.get('recipe', '?')}",
        f"network         {c.get('members', 1)} member(s), hidden {c.get('hidden')}, {c.get('activation')}, skip {c.get('skip')}",
        *_rule_lines(meta, str(p)),
    ]
    return lines + _training(meta) + _common(meta) + _identifiability(meta)


def _training(meta: dict) -> list[str]:
    """The epoch training chose and its validation scores, if the history records it; for an
    ensemble, each member's (from a header as the file holds it)."""
    members = meta.get("members") if isinstance(meta.get("members"), list) else None
    chosen = []
    for record in members or [meta]:
        history, best = (record.get("history"), record.get("best_epoch")) if isinstance(record, dict) else (None, None)
        epoch = history[best - 1] if _chosen(history, best) else None
        nan = float("nan")
        chosen.append(
            _epoch_line(len(history), best, epoch.get("val_loss", nan), epoch.get("val_acc", nan)) if isinstance(epoch, dict) else None
        )
    return _training_lines(chosen, bool(members))
