"""What a user or the machine can cause ends in one line that names the cause, or in the right result,
never in a traceback: one row per fault, each met as a user meets it (the command line as a
subprocess, with the machine's fault made real: a file size limit, a lock held by another process, a
server on 127.0.0.1 that is not Dask's), or through the capture API for the physically based camera.
"""

from __future__ import annotations

import itertools
import resource
import signal
import socket
import subprocess
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import get_args, get_type_hints

import mitsuba  # noqa: F401 - a missing Mitsuba must fail these tests, never skip them
import numpy as np
import pytest
from PIL import Image

from optlight.export import STAGING_PREFIX

#: A small problem (a 96² camera, 4 landmarks): the whole solve in seconds.
SMALL = """
[camera]
width = 96
height = 96

[landmarks]
count = 4
"""


def cli(*args: str, cwd: Path, limit_file_size: int | None = None) -> subprocess.CompletedProcess[str]:
    """``optlight ARGS`` as a subprocess in ``cwd``; with ``limit_file_size`` (bytes) no file it
    writes may grow beyond that (RLIMIT_FSIZE; SIGXFSZ ignored, so a write fails with EFBIG)."""

    def limit() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit_file_size, limit_file_size))

    return subprocess.run(
        [sys.executable, "-m", "optlight.cli", *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=300,
        preexec_fn=limit if limit_file_size is not None else None,
    )


def one_line(run: subprocess.CompletedProcess[str], *fragments: str) -> str:
    """The run's one-line error (exit 2, no traceback), holding every fragment."""
    lines = [line for line in run.stderr.splitlines() if line.strip()]
    assert run.returncode == 2, (run.returncode, run.stdout[-2000:], run.stderr[-4000:])
    assert "Traceback" not in run.stdout + run.stderr
    assert len(lines) == 1, run.stderr
    assert lines[0].startswith("optlight: error: "), lines[0]
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    return lines[0]


def solved(run: subprocess.CompletedProcess[str], out: Path) -> None:
    """The run succeeded and wrote ``out``: every figure a PNG that decodes, and nothing beside
    ``out`` in its folder (no staging folder, no lock file)."""
    assert run.returncode == 0, run.stderr[-4000:]
    figures = sorted(out.glob("*.png"))
    assert {"landmarks_cost.png", "landmarks_images.png", "landmarks_histograms.png"} <= {f.name for f in figures}
    for figure in figures:
        with Image.open(figure) as image:
            image.load()
            assert image.size[0] > 100 and image.size[1] > 100
    assert [p.name for p in out.parent.iterdir() if p.name != "problem.toml"] == [out.name]


def write_problem(folder: Path, text: str) -> str:
    path = folder / "problem.toml"
    path.write_text(SMALL + text)
    return str(path)


# --------------------------------------------------------------------------------------------
# The faults
# --------------------------------------------------------------------------------------------


def dark_light(tmp: Path) -> None:
    """Power 0 and ambient 0: every image black, every cost 0; the figures are drawn (the cost
    map's logarithmic colours were refused: "Invalid vmin or vmax")."""
    problem = write_problem(tmp, "[light]\npower = 0.0\nambient = 0.0\n")
    solved(cli("solve", problem, "--out", str(tmp / "out"), cwd=tmp), tmp / "out")


def zero_weight(tmp: Path) -> None:
    """An objective term of weight 0: every cost 0; the figures are drawn."""
    problem = write_problem(tmp, '[[objective.terms]]\nkind = "histogram"\nweight = 0.0\n')
    solved(cli("solve", problem, "--out", str(tmp / "out"), cwd=tmp), tmp / "out")


def every_bsdf(tmp: Path) -> None:
    """Every documented [world] bsdf renders the face (a vertex-coloured mesh), and a sphere of albedo
    scaled past 1, finite and lit; the roughplastic of a textured mesh (a blend of two constant
    roughplastics) renders what Mitsuba's own roughplastic of constant reflectance renders, on the
    same sphere: the mean within 1 %."""
    from optlight.capture.mitsuba import MitsubaCamera
    from optlight.scene import Scene
    from optlight.spec import WorldSpec, problem_from_dict

    bsdfs = get_args(get_type_hints(WorldSpec)["bsdf"])  # the documented options
    assert set(bsdfs) == {"lambertian", "roughplastic", "principled"}
    # the face, and a sphere whose albedo the world scales past 1 (an rgb reflectance must be ≤ 1)
    objects = ({"face": {"resolution": 48}}, {"kind": "sphere", "albedo": 0.8})
    for bsdf, (k, obj) in itertools.product(bsdfs, enumerate(objects)):
        world = {"spp": 8, "bsdf": bsdf, "albedo_scale": 1.5 if k else 1.0}
        problem = problem_from_dict({"object": obj, "camera": {"width": 48, "height": 48}, "world": world})
        scene = Scene.from_problem(problem)
        image = MitsubaCamera(scene, problem.world).capture(scene.sphere.position(0.3, 0.5)).image
        mask = scene.gbuffer.mask
        assert np.isfinite(image).all(), (bsdf, obj)
        assert image[mask].mean() > 0.1 and image[mask].mean() > 20 * image[~mask].mean(), (bsdf, obj)

    def sphere_mean(texture: float) -> float:
        # albedo_texture > 0 makes the sphere a mesh with vertex colours; 0 leaves Mitsuba's exact sphere
        problem = problem_from_dict(
            {
                "object": {"kind": "sphere", "radius_m": 0.1, "albedo": 0.6},
                "camera": {"width": 48, "height": 48},
                "light": {"model": "point", "ambient": 0.0},
                "world": {"spp": 64, "bsdf": "roughplastic", "roughness": 0.15, "specular": 1.0, "albedo_texture": texture},
            }
        )
        scene = Scene.from_problem(problem)
        camera = MitsubaCamera(scene, problem.world)
        assert isinstance(camera._shape, dict) == (texture == 0.0)
        return float(camera.capture(scene.sphere.position(0.4, 0.5)).image[scene.gbuffer.mask].mean())

    exact, textured = sphere_mean(0.0), sphere_mean(1e-9)
    assert abs(textured - exact) < 0.01 * exact


def degenerate_cost_maps(tmp: Path) -> None:
    """The cost map of a sweep that is all 0, all one value, all NaN, or holds ±inf is drawn, its
    colour scale positive and increasing (a logarithmic scale refuses anything else)."""
    from types import SimpleNamespace

    from optlight.viz.drawing import FigureJob
    from optlight.viz.figures import COST_FLOOR, cost_map_figure, log_color_limits

    zenith, azimuth = np.radians([5.0, 15.0, 25.0]), np.linspace(0.0, 2 * np.pi, 8, endpoint=False)
    finite_inf = np.where(np.arange(24).reshape(8, 3) % 5 == 0, np.inf, 2.0)
    for k, cost in enumerate((np.zeros((8, 3)), np.full((8, 3), 0.3), np.full((8, 3), np.nan), finite_inf, -finite_inf)):
        vmin, vmax = log_color_limits(cost)
        assert COST_FLOOR <= vmin < vmax and np.isfinite(vmax)
        landmarks = SimpleNamespace(
            sweep=SimpleNamespace(cost=cost, zenith=zenith, azimuth=azimuth),
            azimuths=azimuth[:2],
            zeniths=zenith[:2],
            landmarks=(),
            view_zenith=0.0,
            resolution=(32, 32),
        )
        png = FigureJob(cost_map_figure, (landmarks, np.radians(30.0)), 60).save(tmp / f"cost_{k}.png")
        with Image.open(png) as image:
            assert image.size[0] > 100
    assert log_color_limits(np.array([4.0, 0.0])) == (4e-5, 4.0)  # five decades below the largest
    assert log_color_limits(np.empty((0, 3))) == (COST_FLOOR, 10 * COST_FLOOR)


ARM = """<?xml version="1.0"?>
<robot name="arm"><link name="base"/>{links}<link name="tool"/>{joints}
<joint name="jt" type="fixed"><parent link="l{n}"/><child link="tool"/><origin xyz="0.05 0 0"/></joint></robot>
"""
AXES = ("0 0 1", "0 1 0", "0 1 0", "0 1 0", "1 0 0")


def arm_urdf(n: int) -> str:
    """A serial arm of ``n`` revolute joints (z, y, y, y, x), links 0.3 m, then a tool frame."""
    links = "".join(f'<link name="l{k}"/>' for k in range(1, n + 1))
    joints = "".join(
        f'<joint name="j{k}" type="revolute"><parent link="{"base" if k == 1 else f"l{k - 1}"}"/>'
        f'<child link="l{k}"/><origin xyz="0 0 0.3"/><axis xyz="{AXES[k - 1]}"/>'
        '<limit lower="-3" upper="3" effort="10" velocity="2"/></joint>'
        for k in range(1, n + 1)
    )
    return ARM.format(links=links, joints=joints, n=n)


def few_joints(tmp: Path) -> None:
    """A user URDF arm of 4 joints is refused by `check`, naming the 5 constraints and its 4 joints
    (the solve ended in a matmul shape error); one of 5 joints passes."""
    for n in (4, 5):
        (tmp / "arm.urdf").write_text(arm_urdf(n))
        problem = write_problem(tmp, '[robot]\nurdf = "arm.urdf"\nframe = "tool"\n')
        run = cli("check", problem, cwd=tmp)
        if n == 4:
            one_line(run, "problem.toml: robot.urdf", "at least 5 joints", "arm.urdf has 4 (j1, j2, j3, j4)")
        else:
            assert run.returncode == 0, run.stderr


def full_disk(tmp: Path) -> None:
    """No file may grow beyond 200 kB (the trajectory CSV is larger): one line naming the folder and
    the cause, and nothing left: no output folder, no staging folder."""
    problem = write_problem(tmp, "")
    run = cli("solve", problem, "--out", str(tmp / "out"), cwd=tmp, limit_file_size=200_000)
    one_line(run, f"cannot write {tmp / 'out'}", "File too large", "nothing was written")
    assert sorted(p.name for p in tmp.iterdir()) == ["problem.toml"]


def locked_out(tmp: Path) -> None:
    """Another process (this one) is writing --out: the run is refused at its start, in one line
    naming the folder, and creates nothing; once the lock is released the same command succeeds and
    leaves nothing but its output."""
    from optlight import locks

    problem = write_problem(tmp, "")
    out = tmp / "out"
    locks.acquire(out)
    try:
        one_line(cli("solve", problem, "--out", str(out), cwd=tmp), f"another optlight run is writing {out}")
        assert sorted(p.name for p in tmp.iterdir()) == ["problem.toml"]
    finally:
        locks.release(out)
    solved(cli("solve", problem, "--out", str(out), cwd=tmp), out)


def killed_holder(tmp: Path) -> None:
    """A process that holds the lock of an output file and is then killed (SIGKILL: no cleanup of
    its own): while it lives `render` into that file is refused; once it is dead the same command
    writes the file, no lock file or stale lock left behind."""
    png = tmp / "face.png"
    render = ("render", "default", "--zenith", "30", "--azimuth", "90", "--out", str(png))
    holder = subprocess.Popen(
        [sys.executable, "-c", f"import sys; from optlight import locks; locks.acquire({str(png)!r}); print(1, flush=True); sys.stdin.read()"],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout is not None and holder.stdout.readline() == "1\n"  # it holds the lock
        one_line(cli(*render, cwd=tmp), f"another optlight run is writing {png}")
        assert list(tmp.iterdir()) == []
    finally:
        holder.kill()
        holder.communicate()
    assert cli(*render, cwd=tmp).returncode == 0
    assert [p.name for p in tmp.iterdir()] == ["face.png"]


def latin1_captures(tmp: Path) -> None:
    """The folder camera's captures.csv saved again in Latin-1 (an image name with é) between two
    rounds: the next round is one line naming the file, the line and the byte, and changes nothing."""
    problem = write_problem(tmp, "")
    out = tmp / "out"
    assert cli("acquire", problem, "--camera", "folder", "--out", str(out), cwd=tmp).returncode == 0
    table = out / "round_00" / "captures.csv"
    lines = table.read_text(encoding="utf-8").splitlines()
    lines[1] = lines[1].replace("r00_000.png", "caf\xe9_000.png")
    table.write_bytes("\n".join(lines).encode("latin-1"))
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    run = cli("acquire", problem, "--camera", "folder", "--out", str(out), cwd=tmp)
    one_line(run, "round_00/captures.csv", "UTF-8", "byte 0xe9 at line 2")
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before


@contextmanager
def tcp_server(answer: bytes | None) -> Iterator[str]:
    """A server on 127.0.0.1 that sends ``answer`` to whoever connects, or (None) accepts and says
    nothing; its address, stopped with its connections when the block ends."""
    server = socket.create_server(("127.0.0.1", 0))
    accepted: list[socket.socket] = []

    def serve() -> None:
        while True:
            try:
                conn, _ = server.accept()
            except OSError:  # closed: the block ended
                return
            accepted.append(conn)
            if answer is not None:
                conn.sendall(answer)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        yield f"tcp://127.0.0.1:{server.getsockname()[1]}"
    finally:
        server.shutdown(socket.SHUT_RDWR)
        server.close()
        thread.join(timeout=10)
        for conn in accepted:
            conn.close()


def batch_spec(tmp: Path) -> str:
    path = tmp / "spec.toml"
    path.write_text(f'problem = "{write_problem(tmp, "")}"\n\n[grid]\n"landmarks.count" = [4]\n')
    return str(path)


def not_dask(tmp: Path) -> None:
    """`batch --scheduler` and `cell --scheduler` at an HTTP server: one line saying it is not a Dask
    scheduler (Dask read its bytes as a message length and tried to allocate 3.07 EiB)."""
    cell_spec = str(Path(__file__).parents[2] / "examples" / "cell_panda.toml")
    with tcp_server(b"HTTP/1.1 200 OK\r\nContent-Length: 0\r\n\r\n" * 4) as address:
        for command, spec in (("batch", batch_spec(tmp)), ("cell", cell_spec)):
            run = cli(command, spec, "--scheduler", address, "--out", str(tmp / command), cwd=tmp)
            one_line(run, f"{address} is not a Dask scheduler")


def silent_server(tmp: Path) -> None:
    """`batch --scheduler` at a server that accepts and says nothing: one line after the 10 s the
    README promises (Dask waited for its handshake for ever)."""
    with tcp_server(None) as address:
        run = cli("batch", batch_spec(tmp), "--scheduler", address, "--out", str(tmp / "out"), cwd=tmp)
    one_line(run, f"no answer from {address} within 10 s")


@dataclass(frozen=True)
class Fault:
    name: str
    run: Callable[[Path], None]


FAULTS = [
    Fault("figures of power 0 and ambient 0", dark_light),
    Fault("figures of an objective term of weight 0", zero_weight),
    Fault("cost maps of constant, empty and non-finite sweeps", degenerate_cost_maps),
    Fault("every [world] bsdf, roughplastic on a vertex-coloured mesh", every_bsdf),
    Fault("a user arm of fewer than 5 joints", few_joints),
    Fault("a full disk (a file size limit)", full_disk),
    Fault("another run writing --out", locked_out),
    Fault("a killed run's lock", killed_holder),
    Fault("a captures.csv that is not UTF-8", latin1_captures),
    Fault("--scheduler at a server that is not Dask", not_dask),
    Fault("--scheduler at a server that says nothing", silent_server),
]


@pytest.mark.parametrize("fault", FAULTS, ids=[f.name for f in FAULTS])
@pytest.mark.slow
def test_machine_fault(fault: Fault, tmp_path: Path) -> None:
    fault.run(tmp_path)
    assert not list(tmp_path.rglob(f"{STAGING_PREFIX}*"))
