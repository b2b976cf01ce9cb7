"""Draw the pipeline figure of the README: drive -> recording -> model -> evaluation -> robot.

Each box is a step, each arrow the command that makes the next step's files, and under each box
the files that step leaves. The file names are those of the command line's help (``terrapref
COMMAND --help``) for the README's own example (a drive recorded as ``me``).

    python scripts/pipeline_figure.py [--out docs/pipeline.png]
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.patches import FancyArrowPatch, FancyBboxPatch  # noqa: E402

OUT = Path(__file__).resolve().parent.parent / "docs" / "pipeline.png"


@dataclass(frozen=True)
class Step:
    """One box: its name, the command that makes it, the files it leaves, its colour."""

    name: str
    command: tuple[str, ...]
    files: tuple[str, ...]
    colour: str


STEPS = (
    Step("Drive", ("you at the window,", "or the synthetic", "driver"), ("teach_course", "313 m, ~5 min"), "#dbe9f6"),
    Step(
        "Recording",
        ("terrapref drive", "  --record me", "terrapref record", "  ... --out me"),
        ("me/", " meta.json", " scenario.yaml", " frames.jsonl", " images/*.png"),
        "#e3f1df",
    ),
    Step("Model", ("terrapref train me", "  --out", "  me.safetensors"), ("me.safetensors", "me.loss.png", "me.checkpoints/"), "#fdf0d5"),
    Step(
        "Evaluation",
        ("terrapref evaluate", "  me.safetensors", "  gen:7 gen:8", "  --out eval"),
        ("eval/", " metrics.json", " gen_7.png", " gen_8.png"),
        "#f6e0e0",
    ),
    Step(
        "Robot",
        ("terrapref export", "  --format onnx", "terrapref ros1", "terrapref ros2"),
        ("me.onnx", "the node: cmd_vel,", " costmap, live view"),
        "#e8e1f3",
    ),
)

BOX_W, BOX_H, GAP = 2.05, 2.6, 0.45  # [in]
LEFT, BOX_Y = 0.15, 0.35  # [in]
LINE = 0.2  # [in] between text lines
COMMAND, FILES = "#1f4e96", "#222222"


def draw(out: Path) -> Path:
    """Draw the figure into ``out`` (PNG) and return it."""
    width = 2 * LEFT + len(STEPS) * BOX_W + (len(STEPS) - 1) * GAP
    height = BOX_Y + BOX_H + 0.15
    fig = plt.figure(figsize=(width, height), dpi=150)
    ax = fig.add_axes((0, 0, 1, 1))
    ax.set_xlim(0, width)
    ax.set_ylim(0, height)
    ax.axis("off")

    for i, step in enumerate(STEPS):
        x = LEFT + i * (BOX_W + GAP)
        top = BOX_Y + BOX_H
        ax.add_patch(
            FancyBboxPatch(
                (x, BOX_Y),
                BOX_W,
                BOX_H,
                boxstyle="round,pad=0.02,rounding_size=0.12",
                facecolor=step.colour,
                edgecolor="#333333",
                linewidth=1.4,
            )
        )
        ax.text(x + BOX_W / 2, top - 0.12, step.name, ha="center", va="top", fontsize=15, fontweight="bold")
        y = top - 0.5
        first = i > 0  # the first box says who drives, in plain type
        ax.text(
            x + 0.12,
            y,
            "\n".join(step.command),
            ha="left",
            va="top",
            fontsize=10.5,
            linespacing=1.3,
            family="monospace" if first else None,
            color=COMMAND if first else FILES,
            fontweight="bold" if first else None,
        )
        y -= LINE * len(step.command) + 0.22
        ax.plot([x + 0.12, x + BOX_W - 0.12], [y + 0.1, y + 0.1], color="#777777", linewidth=0.8)
        ax.text(x + 0.12, y, "\n".join(step.files), ha="left", va="top", fontsize=10.5, family="monospace", linespacing=1.3, color=FILES)
        if i + 1 < len(STEPS):
            mid = BOX_Y + BOX_H / 2
            ax.add_patch(
                FancyArrowPatch(
                    (x + BOX_W + 0.05, mid),
                    (x + BOX_W + GAP - 0.05, mid),
                    arrowstyle="-|>",
                    mutation_scale=22,
                    linewidth=2.0,
                    color="#333333",
                )
            )

    ax.text(
        width - LEFT,
        0.12,
        "in each box: the command (blue), then the files it writes",
        ha="right",
        va="bottom",
        fontsize=9,
        color="#555555",
    )
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=150, facecolor="white")
    plt.close(fig)
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=OUT, help="PNG to write (default: docs/pipeline.png)")
    args = parser.parse_args()
    print(f"wrote {draw(args.out)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
