"""``fast_init`` (issue 9): the same construction as the dataclass's own ``__init__``."""

from __future__ import annotations

import dataclasses
import inspect

import pytest
from egc_common.frozen import fast_init
from egc_common.messages import BaseCommand
from egc_robot.controller import CommandVerdict, CycleOutput
from egc_robot.filters.egc import EgcResult
from egc_robot.filters.family import FilterResult
from egc_robot.pipeline import PipelineResult
from egc_robot.state_machine import Inputs, Transition


def _fields_and_post_init(cls):
    """The same class body for ``Plain`` and ``Fast``."""
    cls.__annotations__ = {
        "a": "int",
        "b": "float",
        "c": "list[int]",
        "d": "str",
        "e": "tuple[int, ...]",
        "checked": "bool",
    }
    cls.b = 2.5
    cls.c = dataclasses.field(default_factory=list)
    cls.d = dataclasses.field(default="d", init=False)
    cls.e = dataclasses.field(default_factory=tuple, init=False)
    cls.checked = dataclasses.field(default=False, init=False)

    def post_init(self) -> None:
        if self.a < 0:
            raise ValueError("a must be >= 0")
        object.__setattr__(self, "checked", True)

    cls.__post_init__ = post_init
    return cls


@dataclasses.dataclass(frozen=True, slots=True)
@_fields_and_post_init
class Plain:
    pass


@fast_init
@dataclasses.dataclass(frozen=True, slots=True)
@_fields_and_post_init
class Fast:
    pass


def as_tuple(obj: object) -> tuple[object, ...]:
    return tuple(getattr(obj, f.name) for f in dataclasses.fields(obj))  # type: ignore[arg-type]


@pytest.mark.parametrize(
    "args, kwargs",
    [((1,), {}), ((1, 3.5), {}), ((1,), {"c": [4]}), ((), {"a": 2, "b": 0.5, "c": [1, 2]})],
)
def test_same_values_as_the_dataclass_init(args, kwargs):
    plain, fast = Plain(*args, **kwargs), Fast(*args, **kwargs)
    assert as_tuple(plain) == as_tuple(fast)
    assert fast.checked  # __post_init__ ran
    assert Fast(1).c is not Fast(1).c  # a fresh default per instance


def test_still_frozen_and_checked():
    fast = Fast(1)
    with pytest.raises(dataclasses.FrozenInstanceError):
        fast.a = 2  # type: ignore[misc]
    with pytest.raises(ValueError):
        Fast(-1)
    with pytest.raises(TypeError):
        Fast()  # type: ignore[call-arg]
    with pytest.raises(TypeError):
        Fast(1, 2.0, [], 4)  # type: ignore[call-arg]


def test_refuses_what_it_cannot_reproduce():
    @dataclasses.dataclass(frozen=True)
    class NoSlots:
        a: int

    @dataclasses.dataclass(frozen=True, slots=True)
    class WithInitVar:
        a: int
        b: dataclasses.InitVar[int]

        def __post_init__(self, b: int) -> None:
            pass

    for cls in (NoSlots, WithInitVar):
        with pytest.raises(TypeError):
            fast_init(cls)


@pytest.mark.parametrize(
    "cls",
    [
        BaseCommand,
        CommandVerdict,
        CycleOutput,
        EgcResult,
        FilterResult,
        PipelineResult,
        Inputs,
        Transition,
    ],
)
def test_the_robots_classes_keep_their_signature(cls):
    """The classes on the command path: frozen, and called as before."""
    params = list(inspect.signature(cls).parameters.values())
    fields = [f for f in dataclasses.fields(cls) if f.init]
    assert [p.name for p in params] == [f.name for f in fields]
    for p, f in zip(params, fields, strict=True):
        has_default = f.default is not dataclasses.MISSING or (
            f.default_factory is not dataclasses.MISSING
        )
        assert (p.default is not inspect.Parameter.empty) == has_default
        if f.default is not dataclasses.MISSING:
            assert p.default is f.default
    assert cls.__dataclass_params__.frozen  # type: ignore[attr-defined]
