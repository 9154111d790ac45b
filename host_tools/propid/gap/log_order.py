"""The order gap works through its logs in: fixed by the logs' content, not by the order of
the command line.

Some of gap's work depends on where a log sits in the list: the block bootstraps draw
block indices whose order follows the logs, and sums over logs round in list order (the
cross-validation folds do not: with three or more logs each log is a fold of its own). A diagnosis
whose verdict changes when the same logs are given in another order cannot be trusted, so
every list of logs (fitted and held out) is put into one canonical order first: by a digest
of each log's content as read (column names and values), the path only breaking a tie
between two logs of identical content. Renaming or moving a log changes nothing either.
"""

from __future__ import annotations

import hashlib

import numpy as np

from propid.flightlog import FlightLog


def content_digest(log: FlightLog) -> str:
    """SHA-256 over the log's columns in name order: each name, its shape and its values as
    float64 (what the analysis reads, so a reformatted CSV of the same numbers digests alike)."""
    digest = hashlib.sha256()
    for name, values in sorted(log.columns().items()):
        array = np.ascontiguousarray(values, dtype=np.float64)
        digest.update(name.encode("utf-8") + b"\0" + repr(array.shape).encode("ascii"))
        digest.update(array.tobytes())
    return digest.hexdigest()


def canonical_order(logs: list[FlightLog]) -> list[FlightLog]:
    """The logs sorted by content digest (ties, i.e. identical content, by path)."""
    return sorted(logs, key=lambda log: (content_digest(log), str(log.path) if log.path else ""))
