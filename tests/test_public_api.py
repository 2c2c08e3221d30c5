"""The public namespace: what ``dir(flexctrl)`` shows, and that every name documents itself.

Modelled on python-control's ``docstrings_test.py`` and ``kwargs_test.py``: every public
name has a numpydoc docstring; every keyword a public function or class takes is in its
``Parameters`` section (a dataclass may list its fields under ``Attributes``).
"""

import inspect

import pytest
from numpydoc.docscrape import ClassDoc, FunctionDoc

import flexctrl as fc

PUBLIC = sorted(set(fc.__all__) - {"__version__"})


def _documented_parameters(obj) -> set[str]:
    doc = ClassDoc(obj) if inspect.isclass(obj) else FunctionDoc(obj)
    names = set()
    sections = ["Parameters", "Other Parameters"] + (["Attributes"] if inspect.isclass(obj) else [])
    for param in [p for section in sections for p in doc[section]]:
        for name in param.name.split(","):
            names.add(name.strip().lstrip("*"))
    return names


def _signature(obj) -> inspect.Signature | None:
    try:
        return inspect.signature(obj)
    except (TypeError, ValueError):
        return None


def undocumented_parameters(obj) -> list[str]:
    """The parameters of ``obj``'s signature that its docstring's Parameters section lacks."""
    signature = _signature(obj)
    if signature is None:
        return []
    documented = _documented_parameters(obj)
    return [
        name
        for name, p in signature.parameters.items()
        if name not in ("self", "cls") and name not in documented
    ]


def test_dir_lists_only_the_api():
    assert sorted(dir(fc)) == sorted(fc.__all__)
    assert "__version__" in fc.__all__ and fc.__version__


@pytest.mark.parametrize("name", PUBLIC)
def test_every_public_name_has_a_docstring_with_a_summary(name):
    obj = getattr(fc, name)
    doc = inspect.getdoc(obj) or ""
    assert doc.strip(), f"flexctrl.{name} has no docstring"
    summary = doc.strip().splitlines()[0]
    assert summary.endswith((".", ":")), f"flexctrl.{name}: summary line {summary!r}"


@pytest.mark.parametrize(
    "name",
    [n for n in PUBLIC if inspect.isfunction(getattr(fc, n)) or inspect.isclass(getattr(fc, n))],
)
def test_every_keyword_of_a_public_callable_is_documented(name):
    obj = getattr(fc, name)
    if inspect.isclass(obj) and issubclass(obj, BaseException):
        return
    assert undocumented_parameters(obj) == [], f"flexctrl.{name}"


def test_the_keyword_check_can_fail():
    def documented(a, b=1):
        """Do something.

        Parameters
        ----------
        a : int
            The first.
        """

    assert undocumented_parameters(documented) == ["b"]
