"""Many plans at once: a batch of problems solved on a Dask cluster.

A *batch spec* (TOML) names a base problem and the problems to solve as overrides of its keys, written
as dotted problem-file keys (``robot.base_position_m``, ``object.kind``, ``landmarks.count`` …)::

    description = "two robots, three base placements"
    problem = "default"          # the base problem: a built-in name, or a path relative to this file
    preview = false              # write preview.html in every plan folder (~15 MB each for the panda)

    [grid]                       # every combination of these values (a cartesian product)
    "robot.name" = ["panda", "xarm7"]
    "robot.base_position_m" = [[0.0, 0.0, 0.0], [0.05, 0.0, 0.0], [0.0, 0.05, 0.0]]

    [[rows]]                     # and/or listed rows, each a set of overrides (× the grid when both)
    label = "close"              # optional: names the row's folder
    "robot.base_position_m" = [0.1, 0.0, 0.0]

The spec is checked whole before any work starts: the rows are counted (at most :data:`MAX_ROWS`),
then every row's problem is built and validated like a problem file, and a mistake is a
:class:`~optlight.errors.ProblemError` naming the batch file and the key (``grid.robot.name[1]``,
``rows[2].landmarks.count``).

Each row is one task, ``optlight.solve(problem)`` then ``plan.save(folder)`` on a worker
(:func:`solve_row`), into ``OUT/plans/<row>/``: the workers of a local cluster write there
themselves; those of a remote cluster return the folder's files and the client writes them, so they
need no shared file system (``shared_out`` when they do share ``OUT``; they do need the problem's
own files — a mesh, a URDF, a reference image — at the same paths). A row that raises (an unreachable landmark, a
plan that fails verification, anything) is recorded as failed with its error and the batch goes on.
Warnings of the solve (UserWarning: dropped or moved landmarks) are kept per row. After each row,
``OUT/records/<row>.json`` records it; a run in the same ``OUT`` skips the rows already done (their
record says so and their folder holds ``plan.json``) and solves the rest, failed ones included. The
results table of every row, ``OUT/results.csv`` and ``OUT/results.md``, is written at the end.
``OUT`` must be new or empty, or hold an earlier batch (its :data:`BATCH_MARKER`, written first):
optlight never writes among files it did not write (the output policy of :mod:`optlight.export`;
each plan folder is written whole, and one a stopped run left is replaced only as its manifest says).

The engine (a local or remote Dask cluster, the scheduler's check) is :mod:`optlight.engine`'s.
Worker processes are spawned, so a script that calls :func:`run_batch` needs the usual ``if __name__
== "__main__":`` guard.
"""

from optlight.batch.records import BatchResult, RowRecord
from optlight.batch.row import solve_row
from optlight.batch.run import BATCH_MARKER, check_batch_folder, run_batch
from optlight.batch.spec import MAX_ROWS, BatchRow, BatchSpec, batch_spec_from_dict, load_batch_spec

__all__ = [
    "BATCH_MARKER",
    "MAX_ROWS",
    "BatchResult",
    "BatchRow",
    "BatchSpec",
    "RowRecord",
    "batch_spec_from_dict",
    "check_batch_folder",
    "load_batch_spec",
    "run_batch",
    "solve_row",
]
