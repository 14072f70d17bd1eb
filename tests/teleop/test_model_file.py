"""Model files are written, read back and refused strictly: version, axis kind, keys, ranges, runnable forms."""
from __future__ import annotations

import pytest

from teleop.config.model_file import (
    ModelExtension,
    ModelFile,
    ModelParameter,
    check_instrument,
    check_runnable,
    file_sha256,
    load_model,
    save_model,
)
from teleop.errors import ConfigError


def _model(**kw) -> ModelFile:
    base = dict(axis="tendon", instrument="sim0", structure="profile_memory",
                base={"K": 1.2, "compliance": 8.0e-5},
                extensions=(ModelExtension("pretension", (ModelParameter("T0", 2.5, "N", 0.0, 50.0),)),),
                per_cycle="profile_memory+pretension", gain={"base": 0.8, "extended": 0.3, "unit": "N"},
                provenance={"recording": "bench.csv", "sha256": "ab" * 32, "span_s": [0.0, 40.0],
                            "project_version": "0.0.0", "written": "2026-11-27"})
    base.update(kw)
    return ModelFile(**base)


def test_a_model_reads_back_as_written(tmp_path):
    path = save_model(_model(), tmp_path / "m" / "sim0.model.yaml")
    m = load_model(path)
    assert m.values() == {"K": 1.2, "compliance": 8.0e-5, "T0": 2.5}
    assert m.model_id == "sim0/tendon/profile_memory+pretension"
    assert m.sha256 == file_sha256(path) and len(m.sha256) == 64
    assert m.provenance["span_s"] == [0.0, 40.0]
    assert not list(tmp_path.glob("m/*.writing"))


def _edit(path, old, new):
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, 1))


@pytest.mark.parametrize("old, new, message", [
    ("version: 1", "version: 2", r"version: model file version 2 is unknown to this program \(it reads version 1\)"),
    ("axis: tendon", "axis: wrist", r"axis: unknown axis kind 'wrist'"),
    ("structure: profile_memory", "structure: capstan", r"structure: 'capstan' is no base model of a tendon axis"),
    ("per_cycle:", "per_cycl:", r"unknown key 'per_cycl'"),
    ("value: 2.5", "value: 80.0", r"extensions\[0\]\.parameters\.T0\.value: 80 N is outside its range \[0, 50\]"),
    ("value: 2.5", "value: .nan", r"extensions\[0\]\.parameters\.T0\.value: expected a finite number"),
    ("format: tsm-teleop model", "format: other", r"format: not a model file"),
])
def test_a_bad_model_file_is_one_line_naming_the_key(tmp_path, old, new, message):
    path = save_model(_model(), tmp_path / "sim0.model.yaml")
    _edit(path, old, new)
    with pytest.raises(ConfigError, match=message) as e:
        load_model(path)
    assert "\n" not in str(e.value) and str(path) in str(e.value)


def test_a_model_that_would_not_read_back_is_not_written(tmp_path):
    bad = _model(extensions=(ModelExtension("pretension", (ModelParameter("T0", 99.0, "N", 0.0, 50.0),)),))
    with pytest.raises(ConfigError, match="outside its range"):
        save_model(bad, tmp_path / "bad.model.yaml")
    assert not list(tmp_path.iterdir())


def test_an_extension_without_a_per_cycle_form_is_refused_with_its_reason(tmp_path):
    m = load_model(save_model(_model(), tmp_path / "sim0.model.yaml"))
    check_runnable(m, {"pretension": None})
    with pytest.raises(ConfigError, match=r"extensions\[0\]\.id: 'pretension' has no per-cycle form: needs the"):
        check_runnable(m, {"pretension": "needs the distal reading"})
    with pytest.raises(ConfigError, match=r"'pretension' is no tendon catalogue entry"):
        check_runnable(m, {"stiction": None})


def test_a_model_for_another_instrument_or_axis_kind_is_refused(tmp_path):
    m = load_model(save_model(_model(), tmp_path / "sim0.model.yaml"))
    check_instrument(m, "tendon", "sim0")
    with pytest.raises(ConfigError, match="the model is for a tendon axis, the configured instrument is a pair"):
        check_instrument(m, "pair", "sim0")
    with pytest.raises(ConfigError, match="the model is for 'sim0', the configured instrument is 'tsm1'"):
        check_instrument(m, "tendon", "tsm1")
