"""An animation of a run: the mechanism moving (its drawing from `drawings`), the contact force as an arrow,
the contact temperature as the contact's colour where a thermal model ran, and beside it the force (and
temperature) trace with a time cursor.

Frames are blitted by hand: the still parts are rendered once, each frame restores them and redraws only the
moving artists, so 200 frames take a few seconds. GIF through Pillow; MP4 through ffmpeg where it is installed.
"""
from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.cm import ScalarMappable
from matplotlib.figure import Figure
from PIL import Image

from mechsim.dynamics.result import Result
from mechsim.mechanisms.drawing import TEMPERATURE_MAP
from mechsim.scenarios.output.drawings import drawing_for

FRAMES, FPS, DPI = 200, 20, 80
FORMATS = ("gif", "mp4")


def ffmpeg_path() -> str | None:
    """The ffmpeg executable matplotlib would use, or None."""
    from matplotlib import rcParams
    configured = rcParams.get("animation.ffmpeg_path", "ffmpeg")
    return shutil.which(configured) or shutil.which("ffmpeg")


def frame_rows(df: pd.DataFrame, frames: int) -> np.ndarray:
    """Row indices of `frames` instants evenly spread in time over the run (fewer if the run has fewer rows)."""
    t = df["t_s"].to_numpy(float)
    targets = np.linspace(t[0], t[-1], min(frames, len(t)))
    return np.unique(np.clip(np.searchsorted(t, targets), 0, len(t) - 1))


class Animator:
    """The animation's figure and its per-frame update; `frames()` yields RGB arrays."""

    def __init__(self, result: Result, mech, frames: int = FRAMES):
        df = self.df = result.timeseries
        if not len(df):
            raise ValueError("nothing to animate: the run has no output rows")
        drawing_class = mech.drawing_class()
        if drawing_class is None:
            raise ValueError(f"no drawing for a {type(mech).__name__} mechanism")
        self.rows = frame_rows(df, frames)
        force_col = drawing_class.force_column
        thermal = "temp_contact_C" in df and df["temp_contact_C"].notna().any()
        traces = [(force_col, "force (N)", 1.0)] + ([("temp_contact_C", "contact temperature (°C)", 1.0)]
                                                   if thermal else [])
        fig = self.fig = Figure(figsize=(10.5, 5.0), dpi=DPI, layout="constrained")
        grid = fig.add_gridspec(len(traces), 2, width_ratios=[1.15, 1.0])
        self.ax = fig.add_subplot(grid[:, 0])
        self.drawing = drawing_for(self.ax, mech, df)
        if thermal:
            fig.colorbar(ScalarMappable(self.drawing.temperature, TEMPERATURE_MAP), ax=self.ax, shrink=0.7,
                         label="contact temperature (°C)")
        t = df["t_s"].to_numpy(float)
        self.cursors = []
        for i, (col, label, scale) in enumerate(traces):
            ax = fig.add_subplot(grid[i, 1])
            y = df[col].to_numpy(float) * scale if col in df else np.zeros_like(t)
            ax.plot(t, y, lw=1.0, color="tab:blue" if i == 0 else "tab:orange",
                    label=col.replace("_N", "").replace("temp_", "").replace("_C", "").replace("_", " "))
            ax.set_ylabel(label)
            ax.set_xlim(t[0], t[-1])
            ax.grid(alpha=0.3)
            self.cursors.append(ax.axvline(t[0], color="k", lw=1.0))
            if i == len(traces) - 1:
                ax.set_xlabel("time (s)")
        self.clock = self.ax.text(0.02, 0.98, "", transform=self.ax.transAxes, va="top", fontsize=10,
                                  bbox=dict(fc="white", ec="none", alpha=0.8))
        fig.suptitle(f"{result.summary.get('scenario', '')}: arrow = {drawing_class.force_label}")
        self.canvas = FigureCanvasAgg(fig)

    def _moving(self) -> list:
        return self.drawing.update(self.df.iloc[int(self.rows[0])]) + self.cursors + [self.clock]

    def frames(self):
        """RGB frames (H x W x 3 uint8), one per selected row."""
        for artist in self._moving():
            artist.set_animated(True)
        self.canvas.draw()
        background = self.canvas.copy_from_bbox(self.fig.bbox)
        for i in self.rows:
            row = self.df.iloc[int(i)]
            self.canvas.restore_region(background)
            changed = self.drawing.update(row)
            for cursor in self.cursors:
                cursor.set_xdata([row["t_s"], row["t_s"]])
            self.clock.set_text(f"t = {row['t_s']:.3f} s")
            for artist in changed + self.cursors + [self.clock]:
                self.fig.draw_artist(artist)
            yield np.asarray(self.canvas.buffer_rgba())[..., :3].copy()


def write_gif(frames, path: Path, fps: int = FPS) -> Path:
    """GIF through Pillow: one palette (from the first frame) for every frame, looping."""
    frames = iter(frames)
    first = Image.fromarray(next(frames)).quantize(colors=255, method=Image.Quantize.MEDIANCUT)
    rest = [Image.fromarray(f).quantize(palette=first, dither=Image.Dither.NONE) for f in frames]
    first.save(path, save_all=True, append_images=rest, duration=int(round(1000 / fps)), loop=0)
    return Path(path)


def write_mp4(frames, path: Path, fps: int = FPS) -> Path:
    """H.264 MP4 through ffmpeg (raw RGB frames on its standard input)."""
    exe = ffmpeg_path()
    if exe is None:
        raise RuntimeError("MP4 needs ffmpeg, which is not installed; write a GIF instead")
    frames = iter(frames)
    first = next(frames)
    h, w = first.shape[:2]
    cmd = [exe, "-y", "-loglevel", "error", "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", f"{w}x{h}", "-r",
           str(fps), "-i", "-", "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2", "-pix_fmt", "yuv420p", "-vcodec",
           "libx264", str(path)]
    proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        for frame in [first, *frames]:
            proc.stdin.write(frame.tobytes())
    finally:
        proc.stdin.close()
        err = proc.stderr.read().decode(errors="replace").strip()
        proc.wait()
    if proc.returncode:
        raise RuntimeError(f"ffmpeg failed: {err.splitlines()[-1] if err else proc.returncode}")
    return Path(path)


def check_format(fmt: str) -> None:
    """A ScenarioError naming output.animation_format if `fmt` cannot be written here."""
    from mechsim.scenarios.units import ScenarioError
    if fmt not in FORMATS:
        raise ScenarioError("output.animation_format", f"must be one of {', '.join(FORMATS)}, got {fmt!r}")
    if fmt == "mp4" and ffmpeg_path() is None:
        raise ScenarioError("output.animation_format", "mp4 needs ffmpeg, which is not installed; use gif")


def write_animation(result: Result, folder: Path, mechanism=None, fmt: str = "gif", frames: int = FRAMES,
                    fps: int = FPS) -> Path:
    """animation.gif (or .mp4) of the run in `folder`; returns its path."""
    check_format(fmt)
    if mechanism is None:
        from mechsim.scenarios.loader import build_mechanism
        mechanism = build_mechanism(result.scenario)
    images = Animator(result, mechanism, frames).frames()
    path = Path(folder) / f"animation.{fmt}"
    return write_gif(images, path, fps) if fmt == "gif" else write_mp4(images, path, fps)
