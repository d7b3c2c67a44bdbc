"""When a new plan's lead-in points lie (see ``context.Context.lead_in``).

A new plan starts at ``start_t_s`` (the decision, the expected answer, the upload and a
margin) and carries timed points of the UAS's path as flown from ``from_t_s``, the earliest
the vehicle can have it. The points were every ``step_s`` back from the start, never before
``from_t_s``, and none when the window was shorter than a step: a plan installed at
``from_t_s`` then began up to a step later, and until then its position was its first point,
up to a step of flight ahead of the vehicle (100 m for a 20 m/s fixed wing). Monitoring saw
the UAS off its plan, the tracker predicted from that offset, and EM commanded a fixed wing
that was exactly on schedule to hold (it circled into another UAS,
enc_1_0102_merge_overtaking). Here the first point is at ``from_t_s`` itself, so a plan covers
every instant from the moment the vehicle can have it. Pure."""

from __future__ import annotations

import numpy as np

from gcs_utm.model import FloatArray

MIN_WINDOW_S = 0.05
"""A window shorter than this needs no lead-in: the plan starts when the vehicle has it."""


def needs_lead_in(from_t_s: float | None, start_t_s: float) -> bool:
    """Does a plan starting at ``start_t_s`` need lead-in points from ``from_t_s``?"""
    return from_t_s is not None and from_t_s < start_t_s - MIN_WINDOW_S


def lead_times(from_t_s: float, start_t_s: float, step_s: float) -> FloatArray:
    """The lead-in times: ``from_t_s``, then every ``step_s`` back from ``start_t_s`` that is
    more than :data:`MIN_WINDOW_S` after it (the start itself excluded)."""
    k = np.arange(int((start_t_s - from_t_s) // step_s), 0, -1, dtype=np.float64)
    back = start_t_s - step_s * k
    back = back[back > from_t_s + MIN_WINDOW_S]
    return np.concatenate([[from_t_s], back])
