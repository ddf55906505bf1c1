"""Power lines: wires, catenaries, spans, pylons, clearances and load cases.

:func:`extract_powerlines` finds the conductors of an ALS corridor and fits one
catenary per conductor and span (:mod:`.extract`, :mod:`.catenary`);
:mod:`.loads` predicts a span's catenary under another temperature, ice or wind
(the change-of-state equation); :mod:`.output` writes the tables, vector files
and pictures.  docs/powerlines.md.
"""
from __future__ import annotations

from .catenary import CatenaryFit, fit_catenary
from .extract import DEFAULTS, PYLON_CLASS, WIRE_CLASS, Conductor, PowerLines, extract_powerlines
from .loads import CONDUCTORS, LoadCase, parse_load_case, predict_span

_OUTPUT = ("conductor_polylines", "conductor_record", "load_case_records", "write_tables")


def __getattr__(name: str):
    # the writers pull in the vector layer (numba); synth imports this package for its catenaries
    if name in _OUTPUT:
        from . import output

        return getattr(output, name)
    raise AttributeError(f"module 'lidarfx.powerlines' has no attribute {name!r}")


__all__ = ["CONDUCTORS", "DEFAULTS", "PYLON_CLASS", "WIRE_CLASS", "CatenaryFit", "Conductor", "LoadCase", "PowerLines",
           "conductor_polylines", "conductor_record", "extract_powerlines", "fit_catenary", "load_case_records",
           "parse_load_case", "predict_span", "write_tables"]
