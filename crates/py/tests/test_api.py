"""The package as a whole: every public name documented, every public method and property of
every public class documented, every exception under ``stereonav.Error``, the typing marker
shipped."""

from __future__ import annotations

import inspect
import pathlib

import stereonav


def _public(obj: object) -> list[str]:
    return [n for n in dir(obj) if not n.startswith("_")]


def test_every_public_name_has_a_docstring() -> None:
    missing = []
    for name in stereonav.__all__:
        obj = getattr(stereonav, name)
        if isinstance(obj, (int, float, str, tuple, frozenset)) or hasattr(obj, "dtype"):
            continue  # constants and dtypes are documented in the module and the stubs
        if not inspect.getdoc(obj):
            missing.append(name)
    assert not missing, f"no docstring: {missing}"


def test_every_public_member_of_a_public_class_has_a_docstring() -> None:
    missing = []
    for name in stereonav.__all__:
        cls = getattr(stereonav, name)
        if not inspect.isclass(cls) or issubclass(cls, BaseException):
            continue
        for member in _public(cls):
            attr = inspect.getattr_static(cls, member)
            if isinstance(attr, (staticmethod, classmethod)):
                attr = attr.__func__
            if callable(attr) or isinstance(attr, property):
                # NamedTuple fields and tuple methods are documented by the class.
                if member in ("count", "index") and issubclass(cls, tuple):
                    continue
                if not inspect.getdoc(attr):
                    missing.append(f"{name}.{member}")
    assert not missing, f"no docstring: {missing}"


def test_every_exception_derives_from_the_package_error() -> None:
    for name in stereonav.__all__:
        obj = getattr(stereonav, name)
        if inspect.isclass(obj) and issubclass(obj, BaseException):
            assert issubclass(obj, stereonav.Error), name


def test_the_package_ships_its_typing_marker() -> None:
    package = pathlib.Path(stereonav.__file__).parent
    assert (package / "py.typed").exists()
    assert (package / "_native.pyi").exists()
