"""Lattice towers in dense TLS point clouds: members and small parts."""
from __future__ import annotations

from .members import TowerMembers, vectorise_members
from .parts import detect_small_parts

__all__ = ["TowerMembers", "vectorise_members", "detect_small_parts"]
