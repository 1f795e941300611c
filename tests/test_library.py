"""The library API: `from planhrc import …`, the README's example, and imports that stay cheap."""
import re
import subprocess
import sys
from pathlib import Path

import planhrc

README = Path(__file__).resolve().parents[1] / "README.md"


def readme_example() -> str:
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)
    return next(b for b in blocks if b.startswith("from planhrc import"))


def test_the_readme_example_plans_in_five_lines(capsys):
    code = readme_example()
    assert len(code.strip().splitlines()) == 5
    exec(compile(code, "README.md", "exec"), {})
    out = capsys.readouterr().out
    assert out.startswith("solved [") and "('rod_l2', 'rod_l1', 'rod_j1', 'deg_0', 'deg_90')" in out


def test_the_facade_gives_each_layer_its_public_names():
    from planhrc import client, cooperation, model, pipeline, translator, vocabulary

    assert planhrc.make_object is model.make_object and planhrc.perceive is model.perceive
    assert planhrc.translate is translator.translate and planhrc.plan is pipeline.plan
    assert planhrc.decide is cooperation.decide and planhrc.DecisionKind is vocabulary.DecisionKind
    assert planhrc.KBClient is client.KBClient
    assert set(planhrc.__all__) <= set(dir(planhrc)) | {"__version__"}


def test_an_unknown_name_is_an_attribute_error():
    try:
        planhrc.no_such_name  # noqa: B018
    except AttributeError as exc:
        assert "no_such_name" in str(exc)
    else:
        raise AssertionError("planhrc.no_such_name did not raise")


def test_importing_the_model_loads_nothing_above_it():
    code = ("import sys, planhrc, planhrc.model; heavy = [m for m in ('planhrc.pipeline', 'planhrc.translator', "
            "'planhrc.planner', 'planhrc.kb_service', 'fastapi', 'owlready2', 'rdflib') if m in sys.modules]; "
            "print(heavy)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
