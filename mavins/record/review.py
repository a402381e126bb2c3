"""Render a Rerun recording to a PNG with Rerun's own native viewer, headless.

The viewer runs under a private Xvfb X server and draws with Vulkan in
software (Mesa's lavapipe), so no GPU and no desktop are needed::

    Xvfb :N -screen 0 1920x1080x24
    WGPU_BACKEND=vulkan DISPLAY=:N XDG_RUNTIME_DIR=<private dir> \\
        rerun FILE.rrd --renderer vulkan --port 0 --window-size 1600x900 --screenshot-to OUT.png

Debian packages: ``xvfb`` and ``mesa-vulkan-drivers`` (with ``libvulkan1``);
``scripts/install_viewer_deps.sh`` installs them.

Command line (until ``mavins review`` exists)::

    python -m mavins.record.review FILE.rrd --screenshot OUT.png [--size 1600x900] [--timeout 120]
"""

from __future__ import annotations

import argparse
import ctypes.util
import glob
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import warnings
from collections.abc import Sequence
from pathlib import Path

from ..common.argcheck import checked

PACKAGES = "xvfb mesa-vulkan-drivers libvulkan1"
INSTALL_HINT = f"install them with: apt-get install -y {PACKAGES} (or scripts/install_viewer_deps.sh)"
ICD_DIRS = ("/usr/share/vulkan/icd.d", "/etc/vulkan/icd.d", "/usr/local/share/vulkan/icd.d")
XVFB_SCREEN = "1920x1080x24"  # at least; grown to fit the window
RRD_MAGIC = b"RRF"  # every Rerun file starts with it (RRF2 since 0.x)
MIN_SIZE, MAX_SIZE = (200, 150), (8192, 8192)  # window size in points


class ViewerUnavailable(RuntimeError):
    """Something the headless viewer needs is not installed (the message says which package)."""


class ScreenshotError(RuntimeError):
    """The viewer ran but did not produce the picture (the message has the end of its log)."""


def rerun_binary() -> list[str]:
    """Command that starts the native viewer of the installed rerun-sdk."""
    try:
        import rerun_cli  # the wheel's package that holds the viewer binary

        exe = Path(rerun_cli.__file__).with_name("rerun")
        if exe.is_file() and os.access(exe, os.X_OK):
            return [str(exe)]
    except ImportError:
        pass
    beside = Path(sys.executable).with_name("rerun")
    if beside.is_file():
        return [str(beside)]
    found = shutil.which("rerun")
    if found:
        return [found]
    raise ViewerUnavailable("the Rerun viewer binary was not found: install rerun-sdk (pip install rerun-sdk)")


def software_vulkan_icd() -> str:
    """Path of Mesa's software Vulkan driver manifest (lavapipe); raises if it or the loader is missing."""
    if ctypes.util.find_library("vulkan") is None and not glob.glob("/usr/lib/*/libvulkan.so.1"):
        raise ViewerUnavailable(f"the Vulkan loader (libvulkan.so.1) is missing: {INSTALL_HINT}")
    for d in ICD_DIRS:
        hits = sorted(glob.glob(os.path.join(d, "lvp_icd*.json")))
        if hits:
            return hits[0]
    raise ViewerUnavailable(
        f"Mesa's software Vulkan driver (lavapipe, lvp_icd*.json in {ICD_DIRS[0]}) is missing: {INSTALL_HINT}")


def check_dependencies() -> tuple[str, str]:
    """(Xvfb path, lavapipe ICD path); raises :class:`ViewerUnavailable` naming the missing package."""
    xvfb = shutil.which("Xvfb")
    if xvfb is None:
        raise ViewerUnavailable(f"Xvfb (Debian package xvfb) is not installed: {INSTALL_HINT}")
    return xvfb, software_vulkan_icd()


def _start_xvfb(xvfb: str, log_path: Path, screen: str = XVFB_SCREEN,
                timeout: float = 10.0) -> tuple[subprocess.Popen[bytes], int]:
    """Start Xvfb on the first free display number (``-displayfd``); return (process, number)."""
    r, w = os.pipe()
    with open(log_path, "wb") as log:
        proc = subprocess.Popen(
            [xvfb, "-displayfd", str(w), "-screen", "0", screen, "-nolisten", "tcp", "-noreset"],
            stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT, pass_fds=(w,), start_new_session=True)
    os.close(w)
    data = b""
    deadline = time.monotonic() + timeout
    try:
        os.set_blocking(r, False)
        while not data.endswith(b"\n") and time.monotonic() < deadline and proc.poll() is None:
            try:
                chunk = os.read(r, 64)
            except BlockingIOError:
                time.sleep(0.02)
                continue
            if not chunk:
                break
            data += chunk
    finally:
        os.close(r)
    if not data.strip().isdigit():
        _stop(proc)
        tail = log_path.read_text(errors="replace")[-2000:]
        raise ScreenshotError(f"Xvfb did not start (exit code {proc.returncode}):\n{tail}")
    return proc, int(data.strip())


def _park_pointer(display: int, x: int, y: int) -> None:
    """Move the X pointer to (x, y), away from the viewer: a hovered 3D view draws a tooltip. Best effort."""
    try:
        lib = ctypes.CDLL(ctypes.util.find_library("X11") or "libX11.so.6")
        lib.XOpenDisplay.restype = ctypes.c_void_p
        lib.XOpenDisplay.argtypes = [ctypes.c_char_p]
        lib.XDefaultRootWindow.restype = ctypes.c_ulong
        lib.XDefaultRootWindow.argtypes = [ctypes.c_void_p]
        lib.XWarpPointer.argtypes = [ctypes.c_void_p, ctypes.c_ulong, ctypes.c_ulong] + [ctypes.c_int] * 2 + \
            [ctypes.c_uint] * 2 + [ctypes.c_int] * 2
        lib.XFlush.argtypes = [ctypes.c_void_p]
        lib.XCloseDisplay.argtypes = [ctypes.c_void_p]
        dpy = lib.XOpenDisplay(f":{display}".encode())
        if not dpy:
            return
        lib.XWarpPointer(dpy, 0, lib.XDefaultRootWindow(dpy), 0, 0, 0, 0, x, y)
        lib.XFlush(dpy)
        lib.XCloseDisplay(dpy)
    except (OSError, AttributeError):
        pass


def _stop(proc: subprocess.Popen[bytes], grace: float = 5.0) -> None:
    """Terminate a process group we started, then kill it if it lingers."""
    if proc.poll() is not None:
        return
    try:
        os.killpg(proc.pid, signal.SIGTERM)
    except ProcessLookupError:
        return
    try:
        proc.wait(grace)
    except subprocess.TimeoutExpired:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        proc.wait(grace)


def _resize(png: Path, size: tuple[int, int]) -> None:
    """Scale the picture to ``size`` pixels if the viewer drew it at another scale (HiDPI)."""
    from PIL import Image  # a dependency of rerun-sdk

    with Image.open(png) as im:
        if im.size == tuple(size):
            return
        out = im.convert("RGB").resize(size, Image.LANCZOS)
    out.save(png, optimize=True)


def review_blueprint(rrd: Path, out_rbl: Path) -> None:
    """Write ``out_rbl``: the recording's stored blueprint, set up to show the whole run.

    The layout (containers, views, shares) is copied chunk by chunk from the
    blueprint stored in ``rrd``; on top of it the time panel is set to
    *following* (cursor on the newest data, so the 3D view and the text log
    show the whole run), every time-series view's x axis spans all the data
    (following alone scrolls the plots to the last stretch) and the blueprint
    and selection panels are hidden. Without a stored blueprint the viewer's
    automatic layout is used.
    """
    import rerun as rr
    import rerun.blueprint as rrb
    from rerun.chunk import RrdReader

    reader = RrdReader(str(rrd))
    recs = reader.recordings()
    if not recs:
        raise ScreenshotError(f"{rrd}: no recording in the file")
    app = recs[0].application_id
    parts = (rrb.TimePanel(state="collapsed", play_state="following"), rrb.BlueprintPanel(state="hidden"),
             rrb.SelectionPanel(state="hidden"))
    stored = [b for b in reader.blueprints() if b.application_id == app]
    if not stored:
        rrb.Blueprint(*parts, auto_layout=True, auto_views=True).save(app, str(out_rbl))
        return
    from rerun import bindings  # pinned rerun-sdk: the same calls Blueprint.save() makes

    stream = rr.RecordingStream._from_native(bindings.new_blueprint(
        application_id=app, make_default=False, make_thread_default=False, default_enabled=True))
    chunks = list(reader.stream(store=stored[-1]))
    stream.send_chunks(chunks)
    series_views = set()
    for ch in chunks:
        if ch.entity_path.startswith("/view/") and ch.entity_path.count("/") == 2:
            batch = ch.to_record_batch()
            if "ViewBlueprint:class_identifier" in batch.schema.names:
                kinds = batch.column(batch.schema.get_field_index("ViewBlueprint:class_identifier")).to_pylist()
                if any(k and k[0] == "TimeSeries" for k in kinds):
                    series_views.add(ch.entity_path)
    stream.set_time("blueprint", sequence=2**62)  # after every stored row: these values win
    for part in parts:
        part._log_to_stream(stream)
    whole = rrb.TimeAxis(view_range=rrb.TimeRange(start=rrb.TimeRangeBoundary.infinite(),
                                                  end=rrb.TimeRangeBoundary.infinite()))
    for view in sorted(series_views):
        stream.log(f"{view}/TimeAxis", whole)
    bindings.save_blueprint(str(out_rbl), stream.to_native())


def screenshot(rrd: Path, out_png: Path, size: tuple[int, int] = (1600, 900), timeout: float = 120,
               *, at_end: bool = True, native_scale: bool = False) -> None:
    """Render the recording ``rrd`` to ``out_png`` with Rerun's native viewer, headless.

    The viewer opens the file with the recording's own blueprint (layout) in a
    window of ``size`` logical points, under a private Xvfb server with Vulkan
    software rendering, saves a screenshot once the data has loaded and quits.
    The viewer draws at 2 pixels per point; the PNG is scaled to ``size``
    pixels unless ``native_scale`` is set.

    With ``at_end`` (the default) the stored layout is loaded again from a
    temporary ``.rbl`` (see :func:`review_blueprint`) with the time cursor on
    the newest data and the side panels hidden, so the 3D view and the text
    log show the whole run; without it the picture is the viewer's opening
    state (cursor near the start, where the stored blueprint puts it).

    Environment: ``WGPU_BACKEND=vulkan``, ``DISPLAY`` of the started Xvfb,
    a private ``XDG_RUNTIME_DIR`` (mode 700) and the lavapipe driver only
    (``VK_DRIVER_FILES``/``VK_ICD_FILENAMES``), so the result does not depend
    on a GPU. The viewer's own gRPC port is chosen by the system
    (``--port 0``, bound to 127.0.0.1). Xvfb and the viewer are stopped on
    return, also on error or timeout.

    Raises ``FileNotFoundError`` (no recording), :class:`ViewerUnavailable`
    (Xvfb, the Vulkan loader or lavapipe missing: the message names the Debian
    packages ``xvfb`` and ``mesa-vulkan-drivers``) or :class:`ScreenshotError`
    (the viewer failed or timed out: the message holds the end of its log).
    """
    rrd = Path(rrd)
    out_png = Path(out_png)
    w, h = (int(size[0]), int(size[1]))
    if not (MIN_SIZE[0] <= w <= MAX_SIZE[0] and MIN_SIZE[1] <= h <= MAX_SIZE[1]):
        raise ValueError(f"window size {w}x{h} is outside {MIN_SIZE[0]}x{MIN_SIZE[1]}..{MAX_SIZE[0]}x{MAX_SIZE[1]}")
    check_recording(rrd)
    from mavins.common.files import atomic_output, check_outputs

    check_outputs({"--screenshot": out_png}, {"FILE.rrd": rrd})
    xvfb, icd = check_dependencies()
    cmd = rerun_binary()
    # the picture is drawn into a temporary file beside OUT.png, renamed into place once complete
    with atomic_output(out_png) as png:
        png.unlink()  # the viewer must create it: its absence tells that it failed
        _render(rrd, png, cmd, xvfb, icd, w, h, timeout, at_end)
        if not native_scale:
            _resize(png, (w, h))


def check_recording(rrd: Path) -> None:
    """Refuse a file that is not a readable Rerun recording with a recording in it (FileNotFoundError or ValueError)."""
    rrd = Path(rrd)
    if not rrd.is_file():
        raise FileNotFoundError(f"{rrd}: no such recording")
    with open(rrd, "rb") as fh:
        head = fh.read(8)
    if not head:
        raise ValueError(f"{rrd}: the file is empty (expected a Rerun recording, .rrd)")
    if not head.startswith(RRD_MAGIC):
        from mavins.common.files import FOUND, sniff

        found = FOUND.get(sniff(head) or "", "")
        raise ValueError(f"{rrd}: expected a Rerun recording (.rrd, starting with 'RRF'), found "
                         + (found if found else f"bytes {head.hex(' ')}"))
    try:
        from rerun.chunk import RrdReader

        recs = RrdReader(str(rrd)).recordings()
    except Exception as exc:  # the reader's own errors on a damaged file
        raise ValueError(f"{rrd}: not a readable Rerun recording: {exc}") from None
    if not recs:
        raise ValueError(f"{rrd}: expected a Rerun recording, found a file with no recording in it")


def _render(rrd: Path, out_png: Path, cmd: list[str], xvfb: str, icd: str, w: int, h: int, timeout: float,
            at_end: bool) -> None:
    """Run the viewer under a private Xvfb until it wrote ``out_png``."""
    with tempfile.TemporaryDirectory(prefix="mavins-review-") as tmp:
        tmpdir = Path(tmp)
        runtime = tmpdir / "xdg-runtime"
        runtime.mkdir(mode=0o700)
        os.chmod(runtime, 0o700)
        viewer_log = tmpdir / "viewer.log"
        # the viewer draws at 2 px/pt: a screen larger than the window leaves room to park the pointer
        sw, sh = max(1920, 2 * w + 64), max(1080, 2 * h + 64)
        xserver, display = _start_xvfb(xvfb, tmpdir / "xvfb.log", f"{sw}x{sh}x24")
        _park_pointer(display, sw - 1, sh - 1)
        viewer: subprocess.Popen[bytes] | None = None
        try:
            env = dict(os.environ)
            env.update({
                "DISPLAY": f":{display}",
                "WGPU_BACKEND": "vulkan",
                "XDG_RUNTIME_DIR": str(runtime),
                "VK_DRIVER_FILES": icd,
                "VK_ICD_FILENAMES": icd,
                # warnings become toasts drawn over the views ("running in Docker", "software rasterizer")
                "RUST_LOG": env.get("RUST_LOG", "error"),
            })
            env.pop("WAYLAND_DISPLAY", None)
            files = [str(rrd.resolve())]
            if at_end:  # after the recording: the viewer activates the blueprint loaded last
                rbl = tmpdir / "review.rbl"
                try:
                    review_blueprint(rrd, rbl)
                    files.append(str(rbl))
                except Exception as exc:  # private rerun API changed: the stored layout as opened is still useful
                    warnings.warn(f"cannot set the viewer to the end of the run ({exc}); "
                                  "rendering the recording as it opens", RuntimeWarning, stacklevel=2)
            args = [*cmd, *files, "--renderer", "vulkan", "--port", "0", "--bind", "127.0.0.1",
                    "--window-size", f"{w}x{h}", "--screenshot-to", str(out_png.resolve())]
            with open(viewer_log, "wb") as log:
                viewer = subprocess.Popen(args, env=env, cwd=tmpdir, stdin=subprocess.DEVNULL, stdout=log,
                                          stderr=subprocess.STDOUT, start_new_session=True)
            try:
                rc = viewer.wait(timeout)
            except subprocess.TimeoutExpired:
                raise ScreenshotError(f"the viewer took longer than {timeout:g} s:\n{_tail(viewer_log)}") from None
            if rc != 0 or not out_png.is_file() or out_png.stat().st_size == 0:
                raise ScreenshotError(f"the viewer exited with code {rc} without writing {out_png}:\n"
                                      f"{_tail(viewer_log)}")
        finally:
            if viewer is not None:
                _stop(viewer)
            _stop(xserver)


def _tail(path: Path, n: int = 3000) -> str:
    try:
        return path.read_text(errors="replace")[-n:]
    except OSError:
        return "(no log)"


class _Size:
    """``--size WxH`` within MIN_SIZE..MAX_SIZE (the range is shown in --help)."""

    __name__ = "size"
    metavar = "WxH"

    def describe(self, metavar: str | None = None) -> str:
        return f"W in {MIN_SIZE[0]}..{MAX_SIZE[0]}, H in {MIN_SIZE[1]}..{MAX_SIZE[1]}"

    def __call__(self, text: str) -> tuple[int, int]:
        return checked(text, self._parse, self._inside, "WIDTHxHEIGHT, e.g. 1600x900", self.describe())

    @staticmethod
    def _parse(text: str) -> tuple[int, int]:
        w, h = str(text).lower().split("x")
        return int(w), int(h)

    @staticmethod
    def _inside(size: tuple[int, int]) -> bool:
        return MIN_SIZE[0] <= size[0] <= MAX_SIZE[0] and MIN_SIZE[1] <= size[1] <= MAX_SIZE[1]


class _Seconds:
    """``--timeout S``: a finite number of seconds > 0 (the range is shown in --help)."""

    __name__ = "seconds"
    metavar = "S"

    def describe(self, metavar: str | None = None) -> str:
        return f"{metavar or self.metavar} > 0"

    def __call__(self, text: str) -> float:
        import math

        return checked(text, float, lambda v: math.isfinite(v) and v > 0, f"a number, {self.describe()}",
                       self.describe())


_size = _Size()


DESCRIPTION = ("Render a Rerun recording to a PNG with Rerun's native viewer, headless "
               "(Xvfb + Vulkan software rendering; Debian packages xvfb and mesa-vulkan-drivers).")


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``mavins review`` (also ``python -m mavins.record.review``)."""
    p.add_argument("rrd", type=Path, metavar="FILE.rrd", help="recording to render")
    p.add_argument("--screenshot", type=Path, required=True, metavar="OUT.png", help="PNG to write")
    p.add_argument("--size", type=_Size(), default=(1600, 900), metavar="WxH",
                   help=f"window size (default 1600x900; {_Size().describe()})")
    p.add_argument("--timeout", type=_Seconds(), default=120.0, metavar="S",
                   help="give up after S seconds (default 120; S > 0)")
    p.add_argument("--as-opened", action="store_true",
                   help="the viewer's opening state (cursor near the start, side panels as stored) instead of "
                        "the whole run with side panels hidden")
    p.add_argument("--native-scale", action="store_true", help="keep the viewer's pixel scale (2x the window size)")


def run(args: argparse.Namespace, prog: str) -> int:
    """Render as the parsed options say: 0 on success, 1 on viewer failure, 2 on bad usage."""
    try:
        screenshot(args.rrd, args.screenshot, args.size, args.timeout, at_end=not args.as_opened,
                   native_scale=args.native_scale)
    except (FileNotFoundError, ValueError) as exc:  # the recording or the options (DataFileError too)
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 2
    except (ViewerUnavailable, ScreenshotError) as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 1
    print(f"{prog}: wrote {args.screenshot}", file=sys.stderr)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m mavins.record.review FILE.rrd --screenshot OUT.png``."""
    p = argparse.ArgumentParser(prog="python -m mavins.record.review", description=DESCRIPTION)
    add_arguments(p)
    return run(p.parse_args(argv), p.prog)

if __name__ == "__main__":
    sys.exit(main())
