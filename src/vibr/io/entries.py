"""The views a loader keeps: a user's ``views`` selection applied to a format's entries."""

from __future__ import annotations

import os

from ..errors import VibrInputError


def select_entries(entries: list[dict], views, root=None) -> list[dict]:
    """Pick the loader entries named by ``views`` (positions or names/stems), in that order."""
    if views is None:
        return entries
    if isinstance(views, (str, int)):
        views = [views]
    names = [e["name"] for e in entries]
    out, seen = [], set()
    for k in views:
        if isinstance(k, int) or (isinstance(k, str) and k.strip().lstrip("-").isdigit() and k.strip() not in names):
            i = int(k)
            if not 0 <= i < len(entries):  # -1 is an error, not the last view
                raise VibrInputError(f"no view {i}: the scene has {len(entries)} views "
                                     f"(indices 0 to {len(entries) - 1})", root)
        else:
            k = str(k).strip()
            stem = os.path.splitext(k)[0]
            if k in names:
                i = names.index(k)
            elif stem in names:
                i = names.index(stem)
            else:
                raise VibrInputError(
                    f"no view named {k!r} (views: {', '.join(names[:6])}{', ...' if len(names) > 6 else ''})", root)
        if i in seen:
            raise VibrInputError(f"view {names[i]} is listed twice", root)
        seen.add(i)
        out.append(entries[i])
    if not out:
        raise VibrInputError("no views selected", root)
    return out

