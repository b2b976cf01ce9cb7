"""Commands that train: train, recipes."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from terrapref.cli.common import add_classes_arg, add_force_arg, by_recording, check_table, output_path, warn_partial
from terrapref.configargs import finite_float
from terrapref.errors import UserError
from terrapref.fileio import check_distinct, check_output, check_tensor_file

if TYPE_CHECKING:  # for the hints only: the command line imports what a command needs when it runs
    from terrapref.dataset import Dataset
    from terrapref.learning.train import EpochMetrics, TrainConfig, TrainResult
    from terrapref.recipes import Recipe


def _cmd_train(args: argparse.Namespace) -> int:
    from terrapref.learning.pipeline import RunOptions, train_and_save
    from terrapref.learning.train import DATASET
    from terrapref.recipes import DEFAULT_RECIPE, recipe_named, rules_with

    recipe = recipe_named(args.recipe or DEFAULT_RECIPE)
    config = _train_config(args, recipe)
    recipe = replace(recipe, rules=rules_with(recipe, getattr(args, "second_stage", None), getattr(args, "stage_weight", None)))
    check_distinct(args.data, "recording or dataset")
    if missing := next((p for p in args.data if not Path(p).exists()), None):  # said before anything about the output
        raise UserError(str(missing), "no such file")
    check_tensor_file(args.out, "--out")
    check_output(args.out, "--out", args.data, force=args.force)
    _check_beside(Path(args.out), args.data, args.force)
    if args.classes is not None:  # recordings before they are featurised
        from terrapref.demos.recording import read_recording

        for path in (p for p in args.data if p.is_dir()):
            check_table(args, read_recording(path).classes, path)
    data = _training_data(args, recipe)
    _check_rule_data(data, recipe, args.data[0])
    if args.classes is not None:
        from terrapref.terrain import ClassTable

        check_table(args, ClassTable.from_dict(data.meta["classes"], str(args.data[0])), args.data[0])
    for rule in recipe.rules:
        if rule.data() is not None and data.rule_data(rule.type) is None:
            print(
                f"warning: {args.data[0]} carries no data for the {rule.type} rule; {rule.without_data} "
                f"(train from the recordings, or featurize them with --recipe {recipe.name})",
                file=sys.stderr,
            )
    opt, members = config.optimiser, config.classifier.members
    print(
        f"recipe {recipe.name}: training on {len(data)} samples ({len(args.data)} input(s)), {opt.epochs} epochs, "
        f"batch {opt.batch_size}, lr {opt.lr}{f', {members} members' if members > 1 else ''}"
    )
    try:
        result = train_and_save(
            data,
            args.out,
            config,
            rules=recipe.rules,
            recipe=recipe.name,
            options=RunOptions(progress=_epoch_printer(config, args.verbose)),
        )
    except UserError as exc:  # a rule's configuration in a dataset file: named by the file it came from
        raise UserError(str(args.data[0]), exc.problems) if exc.source == DATASET else exc from None
    except KeyboardInterrupt:
        if left := _interrupted_outputs(args.out):
            print(
                f"note: the best epochs so far are in {left} (the model marked interrupted: no decision rules); {args.out} is untouched",
                file=sys.stderr,
            )
        raise
    _report_training(args, config, data, result)
    if left := _interrupted_outputs(args.out):  # an earlier, stopped run's: kept, as every output is, and named
        print(f"note: {left}: left by an earlier run that was interrupted; kept")
    return 0


def _interrupted_outputs(out: Path) -> str:
    """What an interrupted training leaves beside ``out`` (its model so far, its checkpoints), of
    those there, joined by "and"; "" where there is neither."""
    from terrapref.learning.pipeline import checkpoints_path, interrupted_path

    return " and ".join(str(p) for p in (interrupted_path(out), Path(f"{checkpoints_path(out)}.interrupted")) if p.exists())


def _check_beside(out: Path, inputs: list[Path], force: bool) -> None:
    """Refuse, before any work, the files training writes beside the model (its loss curve and its
    checkpoints' folder) where they exist, unless ``force``, as the model itself is."""
    from terrapref.learning.pipeline import checkpoints_path, loss_curve_path

    curve, checkpoints = loss_curve_path(out), checkpoints_path(out)
    check_output(curve, "--out", inputs)
    check_output(checkpoints, "--out", inputs, folder=True)
    for path, what in ((curve, "its loss curve"), (checkpoints, "its checkpoints")):
        if path.exists() and not force:
            raise UserError(
                str(path), f"exists; training writes {what} there: choose another --out, or pass --force to replace it", field="--out"
            )


def _check_rule_data(data: Dataset, recipe: Recipe, source: Path) -> None:
    """Refuse samples the recipe's rules cannot be fitted to, before any work: a second stage whose
    look-ahead starts past the samples' trajectories, offsets with no intended one to fit to."""
    import numpy as np

    from terrapref.rules.second.rule import check_lookahead

    pref = data.feature_config.preference
    try:
        check_lookahead(recipe.rules, pref.n_steps, pref.dt_s)
    except ValueError as exc:
        raise UserError(
            str(source), f"{exc}; featurize with more steps, or train without the second stage", field="features.preference"
        ) from None
    found = data.rule_data("offset")
    if found is not None and not np.isfinite(found[1]["intent_m"]).any():
        raise UserError(
            str(source),
            "no sample holds an intended offset (all NaN): the offset rule has nothing to fit to",
            field="rules.offset.intent_m",
        )


def _train_config(args: argparse.Namespace, recipe: Recipe) -> TrainConfig:
    """The recipe's training configuration with the flags given on the command line on top."""
    from terrapref.configargs import apply_arguments

    try:
        return apply_arguments(args, recipe.train)
    except ValueError as exc:
        # Name the flag where the configuration's check names a field that has one.
        head, _, rest = str(exc).partition(" ")
        flag = head if head.startswith("--") else f"--{head.replace('_', '-')}" if getattr(args, head, None) is not None else None
        raise UserError(flag or "train", rest if flag else str(exc)) from None


def _training_data(args: argparse.Namespace, recipe: Recipe) -> Dataset:
    """The samples to train on: recordings featurised as the recipe needs, and datasets; refused when
    there is nothing to learn."""
    from terrapref.dataset import check_learnable, training_data
    from terrapref.progress import Progress

    recordings = [p for p in args.data if p.is_dir()]
    _warn_recordings(recordings)
    bar = Progress("featurize", len(recordings), enabled=bool(recordings))
    data = training_data(args.data, recipe.features(), recipe.rules, progress=by_recording(bar))
    bar.close()
    check_learnable(data, args.data[0])
    return data


def _warn_recordings(recordings: list[Path]) -> None:
    """A warning for each recording cut short, and for each whose drive had lethal terrain under the footprint."""
    from terrapref.demos.recording import read_recording

    for path in recordings:
        recording = read_recording(path)
        warn_partial(recording)
        contact = recording.lethal_contact()
        if contact is not None:
            print(
                f"warning: {path}: the drive had lethal terrain under the vehicle ({contact}); the model learns from it as driven",
                file=sys.stderr,
            )


def _epoch_printer(config: TrainConfig, verbose: bool) -> Callable[[EpochMetrics], None]:
    """Prints a table of epochs (every tenth, the last, or all when ``verbose``), one per ensemble
    member, each row with the time so far and the time the remaining epochs will take at the pace so far."""
    import time

    from terrapref.progress import time_left

    header = f"{'epoch':>5s} {'train loss':>10s} {'val loss':>9s} {'train acc':>9s} {'val acc':>8s} {'val top3':>8s}  time"
    members, epochs = config.classifier.members, config.optimiser.epochs
    member = 0
    start = time.perf_counter()

    def show(m) -> None:
        nonlocal member
        if m.epoch == 1:
            member += 1
            print(f"member {member}/{members}\n{header}" if members > 1 else header)
        if verbose or m.epoch == epochs or m.epoch % max(1, epochs // 10) == 0:
            done = ((member - 1) * epochs + m.epoch) / (members * epochs)
            print(
                f"{m.epoch:5d} {m.train_loss:10.4f} {m.val_loss:9.4f} {m.train_acc:9.3f} {m.val_acc:8.3f} {m.val_top3:8.3f}  "
                f"{time_left(time.perf_counter() - start, done)}",
                flush=True,
            )

    return show


def _report_training(args: argparse.Namespace, config: TrainConfig, data: Dataset, result: TrainResult) -> None:
    """The loss curve beside the model, the chosen epochs and what the demonstrations show."""
    from dataclasses import asdict

    from terrapref.learning.pipeline import loss_curve_path
    from terrapref.plots import save_loss_curve
    from terrapref.rules.base import STEERING
    from terrapref.terrain import ClassTable

    members = config.classifier.members
    curve = loss_curve_path(args.out)
    save_loss_curve(
        curve,
        [([asdict(h) for h in r.history], r.best_epoch) for r in result.members or [result]],
        title=f"{Path(args.out).name}: {len(data)} samples{f', {members} members' if members > 1 else ''}",
    )
    chosen = []
    for j, r in enumerate(result.members or [result]):
        best = r.history[r.best_epoch - 1]
        label = f"member {j + 1} " if members > 1 else ""
        chosen.append(f"{label}epoch {r.best_epoch}: val loss {best.val_loss:.4f}, val acc {best.val_acc:.3f}")
    if result.steadying is not None:
        print(result.steadying.line())
    table = ClassTable.from_dict(data.meta["classes"], str(args.data[0]))
    lethal = frozenset({table.lethal_column} if table.lethal else ())  # the terrain column the lethal classes share
    print(f"drives: {result.drives or 'argmax'}" + ("" if result.rules else " (C's argmax: the recipe fits no decision rule)"))
    for rule in result.rules:
        note = "" if rule.type == result.drives or rule.kind != STEERING else " (fitted to be reported; it does not steer)"
        print(f"  {rule.describe(data.feature_config.feature_classes, lethal)}{note}")
        for warning in rule.warnings(data.feature_config.feature_classes, lethal):
            print(f"  warning: {warning}")
    if result.identifiability is not None:
        print("what the demonstrations show (stored in the model):")
        for line in result.identifiability.lines_with_order(data.meta.get("profile")):
            print(f"  {line}")
    m = len(data.feature_config.preference.control.w_rps)
    print(
        f"val acc: the share of held-out frames ({config.optimiser.val_fraction:.0%}) whose driven trajectory C ranks first of {m} "
        f"(chance {1 / m:.3f}); neighbours differ by one step of steering, so val top3 and, for the planner, the agreement "
        "`terrapref evaluate` measures say more"
    )
    print(
        f"wrote {args.out} ({'; '.join(chosen)}), {curve}, checkpoints in {Path(args.out).with_name(Path(args.out).stem + '.checkpoints')}"
    )


def train_parser(sub: argparse._SubParsersAction, flags: bool = True) -> None:
    """``train``; its training flags come from TrainConfig's fields (``flags``: built only when
    the command line is a training, since they need the recipes and NumPy)."""
    p = sub.add_parser("train", help="train a planner from recordings or featurised datasets (recipe teach by default)")
    p.add_argument(
        "data",
        nargs="+",
        metavar="DATA",
        type=Path,
        help="recording directories (featurised as the recipe needs) or dataset files from `terrapref featurize`",
    )
    p.add_argument("--out", required=True, type=output_path, help="model file (.safetensors)")
    p.add_argument("--recipe", default=None, metavar="NAME", help="a named recipe (`terrapref recipes`; default: teach)")
    p.add_argument("--verbose", action="store_true", help="print every epoch (default: every tenth)")
    add_classes_arg(p, check=True)
    add_force_arg(p)
    p.set_defaults(func=_cmd_train)
    if flags:
        from terrapref.configargs import add_arguments
        from terrapref.learning.train import TrainConfig
        from terrapref.recipes import DEFAULT_RECIPE, recipe_named

        group = p.add_argument_group("training (defaults shown: recipe teach's; each flag overrides the chosen recipe's value)")
        add_arguments(group, TrainConfig, recipe_named(DEFAULT_RECIPE).train)
        rules = p.add_argument_group("decision rules (terrapref recipes lists each recipe's; the last one fitted drives)")
        rules.add_argument(
            "--second-stage",
            action=argparse.BooleanOptionalAction,
            default=None,
            help="also fit the second stage's linear utility (or, with --no-, leave the recipe's out)",
        )
        rules.add_argument(
            "--stage-weight",
            type=_stage_weight,
            default=None,
            help="the second stage's weight against log F_t in the decision (recipe teach: 5.0)",
        )


def _stage_weight(text: str) -> float:
    """--stage-weight's number: finite, 0 to the most a model file holds."""
    from terrapref.rules.base import MOST_NUMBER

    value = finite_float(text)
    if not 0 <= value <= MOST_NUMBER:
        raise argparse.ArgumentTypeError(f"{text!r} is not between 0 and {MOST_NUMBER:g}")
    return value


def _cmd_recipes(args: argparse.Namespace) -> int:
    from terrapref.recipes import DEFAULT_RECIPE, RECIPES
    from terrapref.rules import rule_roles

    for name, r in RECIPES.items():
        tag = " (default)" if name == DEFAULT_RECIPE else ""
        drives = f"{r.demonstrations} drive{'s' if r.demonstrations > 1 else ''} of {r.course}"
        types = [rule.type for rule in r.rules]
        print(
            f"{name}{tag}: {drives}, {r.train.optimiser.epochs} epochs{f', {r.train.classifier.members} members' if r.train.classifier.members > 1 else ''}; "
            f"rules: {', '.join(types) or 'none'} ({rule_roles(types)})"
        )
        print(f"    {r.summary}")
    return 0


def recipes_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("recipes", help="list the named training recipes (--recipe NAME in train, --recipes in reproduce and select)")
    p.set_defaults(func=_cmd_recipes)
