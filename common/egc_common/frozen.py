"""A faster ``__init__`` for frozen, slotted dataclasses on the robot's command path (issue 9).

A frozen dataclass's generated ``__init__`` stores each field with
``object.__setattr__(self, name, value)``; measured on the robot's command path (run once per
command, from cold caches), those calls cost more than the arithmetic around them. ``fast_init``
gives the class an ``__init__`` with the same signature, defaults, default factories and
``__post_init__`` call that stores each field through its slot's own descriptor instead: the
same effect without the attribute lookups. Everything else the dataclass generated (frozen
``__setattr__``, ``__eq__``, ``__hash__``, ``__repr__``) stays as it is.
"""

from __future__ import annotations

import dataclasses
import inspect
from typing import Any, TypeVar

T = TypeVar("T")

_MISSING = dataclasses.MISSING


def fast_init(cls: type[T]) -> type[T]:
    """Replace ``cls.__init__`` (a frozen, slotted dataclass; decorate above ``@dataclass``)."""
    params = getattr(cls, "__dataclass_params__", None)
    if params is None or not params.frozen or not params.init or "__slots__" not in cls.__dict__:
        raise TypeError(f"{cls.__name__}: fast_init needs a frozen, slotted dataclass with init")
    fields = dataclasses.fields(cls)  # type: ignore[arg-type]
    namespace: dict[str, Any] = {"_MISSING": _MISSING}
    args: list[str] = []
    body: list[str] = []
    for i, f in enumerate(fields):
        if f.kw_only:
            raise TypeError(f"{cls.__name__}: fast_init does not handle keyword-only fields")
        setter = f"_set{i}"
        namespace[setter] = cls.__dict__[f.name].__set__  # the slot's member descriptor
        has_factory = f.default_factory is not _MISSING
        if has_factory:
            namespace[f"_factory{i}"] = f.default_factory
        if f.default is not _MISSING:
            namespace[f"_default{i}"] = f.default
        if f.init:
            if has_factory:
                args.append(f"{f.name}=_MISSING")
                body.append(f"{setter}(self, _factory{i}() if {f.name} is _MISSING else {f.name})")
            elif f.default is not _MISSING:
                args.append(f"{f.name}=_default{i}")
                body.append(f"{setter}(self, {f.name})")
            else:
                args.append(f.name)
                body.append(f"{setter}(self, {f.name})")
        elif has_factory:
            body.append(f"{setter}(self, _factory{i}())")
        elif f.default is not _MISSING:
            body.append(f"{setter}(self, _default{i})")
    if hasattr(cls, "__post_init__"):
        body.append("self.__post_init__()")
    source = f"def __init__(self, {', '.join(args)}):\n" + "".join(
        f"    {line}\n" for line in body or ["pass"]
    )
    exec(source, namespace)
    init = namespace["__init__"]
    before, after = inspect.signature(cls.__init__), inspect.signature(init)
    if [(p.name, p.kind, p.default is p.empty) for p in before.parameters.values()] != [
        (p.name, p.kind, p.default is p.empty) for p in after.parameters.values()
    ]:  # e.g. an InitVar, which only dataclasses' own __init__ passes on
        raise TypeError(f"{cls.__name__}: fast_init cannot reproduce {before}")
    init.__qualname__ = f"{cls.__qualname__}.__init__"
    init.__doc__ = cls.__init__.__doc__
    cls.__init__ = init  # type: ignore[method-assign]
    return cls
