"""Every docstring example of the library runs and prints what it says (doctest), and the
public entry points a newcomer starts from keep theirs."""

from __future__ import annotations

import doctest
import importlib
import pkgutil

import pytest

import vibr

#: functions whose docstring must keep an Examples section
MUST_HAVE = ("vibr.camera.Camera", "vibr.render.api.render", "vibr.synthetic.make_scene", "vibr.synthetic.photograph",
             "vibr.metrics.psnr", "vibr.paths.camera_path.interpolate")


def _tests():
    finder = doctest.DocTestFinder(exclude_empty=True)
    found = {}
    for m in pkgutil.walk_packages(vibr.__path__, "vibr."):
        if m.name.endswith("__main__"):
            continue
        mod = importlib.import_module(m.name)
        for t in finder.find(mod, m.name):
            if t.examples and t.name.startswith(m.name) and t.name not in found:
                found[t.name] = t
    return found


TESTS = _tests()


def test_the_entry_points_have_examples():
    assert set(MUST_HAVE) <= set(TESTS), sorted(set(MUST_HAVE) - set(TESTS))


@pytest.mark.parametrize("name", sorted(TESTS))
def test_docstring_example_runs(name):
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    report = []
    runner.run(TESTS[name], out=report.append)
    assert runner.failures == 0, "".join(report)
