"""The classifier C as an ONNX graph, for runtimes on the robot.

Input ``utilities``, float32 (N, m, k): each frame's utility features U (SPEC 7; k = the
terrain classes + distance). Output ``logits``, float32 (N, m): C's scores, whose softmax is
F_t, computed in float64 inside the graph like the planner's own forward pass (an ensemble's logits are the log of its members' mean softmax, as in
:func:`terrapref.learning.numpy_forward`). Everything the model was trained under (preference
set, camera, classes, profile, feature configuration, the decision rules: the second stage's
linear utility, the offset rule's utility, the speed rule's speeds) is in the model's metadata as
JSON strings under ``terrapref.*`` keys. The offset rule itself (terrapref.rules.offset.rule: a
ground map, the offsets' features, pure pursuit) is not a network and is not in the graph;
``terrapref.runtime`` runs it.

Nor is the speed: C scores the trajectories at the control set's speed (``preference_set.v_mps``),
and the speed along the way chosen is the speed rule's (terrapref.rules.speed), which the planner
runs, not the graph. ``terrapref.speed`` says so: which block of ``terrapref.rules`` is the speed
rule (None: the model has none and drives at the control set's speed), and where the speed is
decided, in words; ``terrapref.rules.rules_in`` reads the rules back, the speed rule among them.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from terrapref.extras import needs
from terrapref.fileio import write_bytes_atomic
from terrapref.learning.model_file import LoadedModel
from terrapref.learning.network import ClassifierConfig, member_prefix
from terrapref.rules import Rule, driving_rule, rules_of, speed_rule

with needs("robot", "ONNX files"):  # this module is imported only for them
    import onnx
    from onnx import TensorProto, helper, numpy_helper

ONNX_FORMAT = "terrapref-onnx/1"
OPSET = 17  # widely supported by runtimes; every operator used here exists since opset 13
INPUT, OUTPUT = "utilities", "logits"


class _Graph:
    """Nodes and constants of one graph, with unique names."""

    def __init__(self) -> None:
        self.nodes: list[onnx.NodeProto] = []
        self.constants: list[onnx.TensorProto] = []
        self._n = 0

    def name(self, stem: str) -> str:
        self._n += 1
        return f"{stem}_{self._n}"

    def const(self, stem: str, value: np.ndarray) -> str:
        name = self.name(stem)
        self.constants.append(numpy_helper.from_array(np.asarray(value), name))
        return name

    def op(self, op_type: str, inputs: list[str], stem: str | None = None, **attrs) -> str:
        out = self.name(stem or op_type.lower())
        self.nodes.append(helper.make_node(op_type, inputs, [out], name=out, **attrs))
        return out


def _member(g: _Graph, c: ClassifierConfig, weights: dict[str, np.ndarray], x: str, prefix: str) -> str:
    """Logits (N, m) of one network for U (N, m, k) named ``x``; mirrors network.stacked_forward for one member."""
    w = lambda name: np.asarray(weights[f"{prefix}{name}"], dtype=np.float64)  # noqa: E731  (the file's float32 values, exactly)
    if c.compress:
        per_row = g.op(
            "Add", [g.op("MatMul", [x, g.const("compress_wT", w("compress.weight").T)]), g.const("compress_b", w("compress.bias"))]
        )
        scores = g.op("Gather", [per_row, g.const("channel0", np.array(0, np.int64))], axis=2)  # (N, m)
        h = g.op("Reshape", [per_row, g.const("flat", np.array([0, c.m], np.int64))])
    else:
        scores = None
        h = g.op("Reshape", [x, g.const("flat", np.array([0, c.m * c.n_features], np.int64))])
    for i in range(c.depth + 1):
        h = g.op("Gemm", [h, g.const(f"layer{i}_w", w(f"layers.{i}.weight")), g.const(f"layer{i}_b", w(f"layers.{i}.bias"))], transB=1)
        if i < c.depth:
            if c.activation == "relu":
                h = g.op("Relu", [h])
            elif c.activation == "tanh":
                h = g.op("Tanh", [h])
            else:  # elu (alpha 1) from primitives: runtimes' Elu kernels are float32 only
                zero = g.const("zero", np.array(0.0))
                negative = g.op("Sub", [g.op("Exp", [g.op("Min", [h, zero])]), g.const("one", np.array(1.0))])
                h = g.op("Where", [g.op("Greater", [h, zero]), h, negative])
    return g.op("Add", [h, scores]) if c.skip else h


def classifier_graph(config: ClassifierConfig, weights: dict[str, np.ndarray]) -> onnx.ModelProto:
    """An ONNX model computing C's logits for a batch of U."""
    g = _Graph()
    # The arithmetic is float64, as the planner's own (float32 weights applied to float64
    # features): logits of rare trajectories reach -69, where float32 alone loses 1e-5.
    x = g.op("Cast", [INPUT], to=TensorProto.DOUBLE)
    if config.ignore:
        keep = np.ones(config.n_features)
        keep[list(config.ignore)] = 0.0
        x = g.op("Mul", [x, g.const("ignore_mask", keep)])
    if config.members == 1:
        logits = _member(g, config, weights, x, "")
    else:
        probs = [g.op("Softmax", [_member(g, config, weights, x, member_prefix(j))], axis=-1) for j in range(config.members)]
        mean = g.op("Mul", [g.op("Sum", probs), g.const("one_over_members", np.array(1.0 / config.members))])
        logits = g.op("Log", [g.op("Add", [mean, g.const("tiny", np.array(1e-30))])])
    g.nodes.append(helper.make_node("Cast", [logits], [OUTPUT], name=OUTPUT, to=TensorProto.FLOAT))
    graph = helper.make_graph(
        g.nodes,
        "terrapref_classifier",
        [helper.make_tensor_value_info(INPUT, TensorProto.FLOAT, ["N", config.m, config.n_features])],
        [helper.make_tensor_value_info(OUTPUT, TensorProto.FLOAT, ["N", config.m])],
        initializer=g.constants,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)], producer_name="terrapref")
    model.ir_version = 8  # readable by runtimes from onnxruntime 1.10 on
    onnx.checker.check_model(model, full_check=True)
    return model


def export_onnx(model: LoadedModel, out: str | Path) -> Path:
    """Write ``model``'s classifier to ``out`` as ONNX, with its configuration in the metadata."""
    proto = classifier_graph(model.classifier, model.weights)
    meta = model.meta
    props = {
        "format": ONNX_FORMAT,
        "classifier": model.classifier.to_dict(),
        "features": model.features.to_dict(),
        "preference_set": {
            "v_mps": model.features.preference.control.v_mps,
            "w_rps": list(model.features.preference.control.w_rps),
            "n_steps": model.features.preference.n_steps,
            "dt_s": model.features.preference.dt_s,
        },
        "camera": model.camera.to_dict(),
        "classes": model.classes.to_dict(),
        "profile": list(model.profile),
        "feature_classes": list(model.features.feature_classes),
    }
    rules, drives = rules_of(model)  # the decision rules' blocks, read (older files' too) and written as this version writes them
    props["rules"] = [rule.header() for rule in rules]
    if drives is not None or rules:
        props["drives"] = driving_rule(rules, drives, model.path).type  # a rule that steers: a speed rule drives no way
    props["speed"] = speed_metadata(rules, model.features.preference.control.v_mps)
    for key in ("recipe", "identifiability", "created", "sources", "fingerprint"):
        if key in meta:
            props[key] = meta[key]
    helper.set_model_props(proto, {f"terrapref.{k}": json.dumps(v) for k, v in props.items()})
    return write_bytes_atomic(out, proto.SerializeToString())


def speed_metadata(rules: tuple[Rule, ...], v_set_mps: float) -> dict:
    """``terrapref.speed``: which of ``rules`` sets the speed (its index in ``terrapref.rules`` and
    its type, None without one) and where the speed is decided, in words; ``v_set_mps`` [m/s] is
    the control set's speed, at which C scores the trajectories."""
    rule = speed_rule(rules)
    if rule is None:
        where = f"no speed rule: the planner commands the control set's speed, {v_set_mps:g} m/s, along the way chosen"
        return {"rule": None, "type": None, "decided_in": "planner", "note": where}
    note = (
        f"the graph holds C alone, which scores the trajectories at the control set's speed ({v_set_mps:g} m/s); "
        f"the speed along the way chosen is the speed rule's (terrapref.rules[{rules.index(rule)}], type {rule.type!r}), "
        "which is not a network and runs in terrapref's planner (terrapref.runtime.PlannerRuntime), not in this graph; "
        "the command is (v, curvature x v) at that speed"
    )
    return {"rule": rules.index(rule), "type": rule.type, "decided_in": "planner", "note": note}


def read_onnx_metadata(path: str | Path) -> dict:
    """The ``terrapref.*`` metadata of an exported model, decoded (no graph is run)."""
    proto = onnx.load(str(path), load_external_data=False)
    return {p.key.removeprefix("terrapref."): json.loads(p.value) for p in proto.metadata_props if p.key.startswith("terrapref.")}
