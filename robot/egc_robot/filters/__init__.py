"""Shared-autonomy filters. Each is a pure function of command, scan points and parameters."""

from egc_robot.filters.egc import EgcCase, EgcParams, EgcResult, Region, Side, egc_filter
from egc_robot.filters.ek_egc import ek_egc_filter, ek_transform

__all__ = [
    "EgcCase",
    "EgcParams",
    "EgcResult",
    "Region",
    "Side",
    "egc_filter",
    "ek_egc_filter",
    "ek_transform",
]
