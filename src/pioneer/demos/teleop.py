"""Keyboard teleoperation: drive the robot yourself and record labelled demonstrations.

Two layers:

* :class:`TeleopController` — the command state and the key bindings, pure Python (no
  pygame). Keys are named by strings (``"up"``, ``"down"``, ``"left"``, ``"right"``,
  ``"space"``, ``"n"``, ``"b"``, ``"r"``, ``"escape"``).
* :class:`TeleopSession` — owns a :class:`~pioneer.envs.env.NavEnv`, a pygame window and the
  output file. :meth:`TeleopSession.tick` processes the pending pygame events, applies the
  current command for one control period (10 Hz) and redraws; :meth:`TeleopSession.run`
  ticks until you quit.

Key bindings: UP/DOWN change v by ±0.1 m/s (clipped to [0, 0.8]); LEFT/RIGHT change ω by
±0.2 rad/s (LEFT turns left, clipped to ±0.4π); SPACE stops (v = ω = 0); N toggles "this whole
episode is negative"; B opens a negative span and B again closes it; R restarts the episode;
ESC or closing the window quits.

Labelling (one value per frame, γ ∈ {−1, +1}): +1 by default; −1 for every frame of an episode
that is marked negative with N when it ends; −1 for the frames recorded while a B span was open
(a span still open at the end of the episode runs to its last frame); on a collision, −1 for
the frames of the last :data:`~pioneer.demos.generate.NEGATIVE_WINDOW` (1.0 s) before it,
selected by :func:`~pioneer.demos.generate.negative_frames`. Nothing is ever promoted from −1
to +1.

Saving: every finished episode — success, collision, timeout, restart (R) or quit (ESC,
window close, Ctrl-C) — is appended to the output file at once: the file is loaded (if it
exists), merged with the episode and rewritten atomically, so closing the window loses nothing.
An unfinished episode (restart or quit) is kept when it has at least one frame, labelled only
by your N/B marks (no collision window, as there was no collision); press N before R or ESC
to keep it as a negative example. Episode ``k`` of a session (counting restarts) is seeded
``seed + k``; the command resets to v = ω = 0 and the N/B marks are cleared at every new
episode.
"""

from __future__ import annotations

import dataclasses
import os
import sys
import types
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pioneer.demos.generate import NEGATIVE_WINDOW, Frame, negative_frames
from pioneer.envs.env import NavEnv
from pioneer.envs.episode import Episode
from pioneer.errors import ConfigError, PioneerError, expect
from pioneer.io import atomic_path
from pioneer.reward.dataset import Dataset
from pioneer.sim.robot import RobotConfig
from pioneer.sim.scenarios import get_scenario

__all__ = [
    "KEYS",
    "TeleopController",
    "TeleopSession",
    "TeleopUnavailableError",
    "label_episode",
]

KEYS = ("up", "down", "left", "right", "space", "n", "b", "r", "escape")
# SDL video drivers without a window: refused unless asked for by SDL_VIDEODRIVER
HEADLESS_DRIVERS = ("offscreen", "dummy")
V_STEP = 0.1  # [m/s] per UP/DOWN press
OMEGA_STEP = 0.2  # [rad/s] per LEFT/RIGHT press
STATUS_HEIGHT = 68  # [px] text area below the scene (three lines)
MIN_WIDTH = 600  # [px] the text needs this much; narrower scenes are centred
MESSAGE_TICKS = 40  # how long an end-of-episode message stays on screen
INSTALL_HINT = "pip install 'pioneer-nav[teleop]'"


class TeleopUnavailableError(PioneerError, ImportError):
    """pygame-ce is not installed (install the ``teleop`` extra)."""


def _import_pygame() -> types.ModuleType:
    os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
    try:
        import pygame
    except ImportError as exc:
        raise TeleopUnavailableError(
            expect("teleop", "pygame-ce installed", f"ImportError ({exc})", INSTALL_HINT)
        ) from exc
    return pygame


class TeleopController:
    """The operator's command (v, ω) and episode marks, changed by key presses.

    :meth:`press` returns ``"restart"`` or ``"quit"`` for the session-level keys R and ESC
    and ``None`` otherwise; unknown key names are ignored.
    """

    name = "operator"

    def __init__(self, robot: RobotConfig | None = None) -> None:
        rc = robot or RobotConfig()
        self.v_min, self.v_max, self.omega_max = rc.v_min, rc.v_max, rc.omega_max
        self.v = 0.0  # [m/s]
        self.omega = 0.0  # [rad/s]
        self.negative = False  # N: the whole episode is negative
        self.span_open = False  # B: frames recorded now are negative

    @property
    def command(self) -> NDArray[np.float64]:
        """The current command ``(v, ω)``."""
        return np.array([self.v, self.omega], dtype=np.float64)

    @property
    def marking_negative(self) -> bool:
        """Whether the frame recorded now will be labelled γ = −1 by the operator."""
        return self.negative or self.span_open

    def new_episode(self) -> None:
        """Stop and clear the N/B marks."""
        self.v = self.omega = 0.0
        self.negative = self.span_open = False

    def reset(self, info: Mapping[str, Any], rng: np.random.Generator) -> None:
        """As a policy: a new episode starts (:meth:`new_episode`)."""
        self.new_episode()

    def act(self, obs: NDArray[np.float32], info: Mapping[str, Any]) -> NDArray[np.float64]:
        """As a policy: the operator's current command."""
        return self.command

    def press(self, key: str) -> str | None:
        """Apply one key press (see :data:`KEYS`)."""
        if key == "up":
            self.v = _clip(self.v + V_STEP, self.v_min, self.v_max)
        elif key == "down":
            self.v = _clip(self.v - V_STEP, self.v_min, self.v_max)
        elif key == "left":
            self.omega = _clip(self.omega + OMEGA_STEP, -self.omega_max, self.omega_max)
        elif key == "right":
            self.omega = _clip(self.omega - OMEGA_STEP, -self.omega_max, self.omega_max)
        elif key == "space":
            self.v = self.omega = 0.0
        elif key == "n":
            self.negative = not self.negative
        elif key == "b":
            self.span_open = not self.span_open
        elif key == "r":
            return "restart"
        elif key == "escape":
            return "quit"
        return None


def _clip(x: float, lo: float, hi: float) -> float:
    # Rounding keeps repeated ±0.1 steps on the grid (0.1 + 0.2 != 0.3 in floating point).
    return round(min(max(x, lo), hi), 9)


def label_episode(
    frames: Sequence[Frame], event: str | None, negative: bool, dt: float
) -> NDArray[np.float64]:
    """γ per frame: +1, or −1 if ``negative`` (N), if ``frame["span"]`` (B), or — after a
    collision — within the last :data:`NEGATIVE_WINDOW` seconds before it."""
    gamma = np.ones(len(frames))
    if negative:
        gamma[:] = -1.0
    for i, f in enumerate(frames):
        if f.get("span", False):
            gamma[i] = -1.0
    if event == "collision" and frames:
        last = {id(f) for f in negative_frames(list(frames), dt)}
        for i, f in enumerate(frames):
            if id(f) in last:
                gamma[i] = -1.0
    return gamma


@dataclasses.dataclass
class _Episode:
    seed: int
    frames: list[Frame] = dataclasses.field(default_factory=list)
    trail: list[tuple[float, float]] = dataclasses.field(default_factory=list)


class TeleopSession:
    """A recording session: one scenario, one output file, many episodes.

    The constructor validates the arguments and an existing output file (so a bad file fails
    before you drive), opens the window and starts episode 0. ``realtime=False`` drops the
    10 Hz frame limiter (tests); ``window_size`` is the longer side of the scene in pixels.
    """

    def __init__(
        self,
        scenario: str,
        out: str | os.PathLike[str],
        seed: int = 0,
        max_episodes: int | None = None,
        realtime: bool = True,
        window_size: int = 640,
        command: str = "",
    ) -> None:
        if max_episodes is not None and max_episodes < 1:
            raise ConfigError(
                expect("max_episodes", "an integer >= 1 (or None)", max_episodes, "raise it")
            )
        if window_size < 100:
            raise ConfigError(expect("window_size", ">= 100 px", window_size, "raise it"))
        self.cfg = get_scenario(scenario)
        self.out = Path(out)
        if self.out.exists():
            Dataset.load(self.out)  # refuse a file we could not append to, before driving
        self.seed = int(seed)
        self.max_episodes = max_episodes
        self.realtime = realtime
        self.window_size = int(window_size)
        self.command = command or (
            f"pioneer teleop --scenario {self.cfg.name} --out {self.out} --seed {self.seed}"
        )
        self.dt = self.cfg.sim.dt
        self.env = NavEnv(self.cfg)
        self.controller = TeleopController(self.cfg.sim.robot)
        self.episodes_started = 0
        self.episodes_saved = 0
        self.frames_saved = 0
        self.negatives_saved = 0
        self.events: list[str] = []  # how each saved episode ended
        self.message = ""
        self._message_ticks = 0
        self.done = False

        self._pg = _import_pygame()
        pg = self._pg
        fix = "run it in a desktop session (SDL_VIDEODRIVER=dummy: headless, no window)"
        if (
            sys.platform.startswith("linux")
            and not os.environ.get("SDL_VIDEODRIVER")
            and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
        ):
            raise PioneerError(
                expect("teleop window", "a display (DISPLAY or WAYLAND_DISPLAY)", "none", fix)
            )
        try:
            pg.display.init()
            pg.font.init()
        except pg.error as exc:
            raise PioneerError(
                expect("teleop window", "a display pygame can open", str(exc), fix)
            ) from exc
        driver = pg.display.get_driver()
        if driver in HEADLESS_DRIVERS and not os.environ.get("SDL_VIDEODRIVER"):
            # SDL fell back to a driver without a window: nobody could see or steer the robot
            pg.display.quit()
            raise PioneerError(
                expect("teleop window", "a display pygame can open", f"only SDL's {driver!r}", fix)
            )
        self._keymap = {
            pg.K_UP: "up",
            pg.K_DOWN: "down",
            pg.K_LEFT: "left",
            pg.K_RIGHT: "right",
            pg.K_SPACE: "space",
            pg.K_n: "n",
            pg.K_b: "b",
            pg.K_r: "r",
            pg.K_ESCAPE: "escape",
        }
        self._clock = pg.time.Clock()
        self._font = pg.font.Font(None, 22)
        self._screen: Any = None
        self._run: Episode
        self._episode = self._start_episode()
        self.render()

    # ------------------------------------------------------------------ episodes
    def _start_episode(self) -> _Episode:
        ep = _Episode(seed=self.seed + self.episodes_started)
        self.episodes_started += 1
        self._run = Episode(self.env, self.controller, ep.seed)
        pose = self._run.info["robot_pose"]
        ep.trail.append((float(pose[0]), float(pose[1])))
        return ep

    @property
    def frames(self) -> list[Frame]:
        """The frames recorded so far in the current episode."""
        return self._episode.frames

    @property
    def time(self) -> float:
        """Simulated time of the current episode [s]."""
        return float(self._run.info["time"])

    def _finish_episode(self, event: str) -> None:
        """Label and save the current episode (if it has frames); the caller starts the next."""
        ep, negative = self._episode, self.controller.negative
        self._episode = _Episode(seed=ep.seed)  # never save the same frames twice
        if not ep.frames:
            return
        gamma = label_episode(ep.frames, event, negative, self.dt)
        self._append(ep, gamma, event)
        n_neg = int(np.sum(gamma < 0))
        self.episodes_saved += 1
        self.frames_saved += len(ep.frames)
        self.negatives_saved += n_neg
        self.events.append(event)
        self._say(f"episode {self.episodes_saved}: {event}, {len(ep.frames)} frames ({n_neg} γ=−1)")
        if self.max_episodes is not None and self.episodes_saved >= self.max_episodes:
            self.done = True

    def _append(self, ep: _Episode, gamma: NDArray[np.float64], event: str) -> None:
        cols = Dataset.columns()
        Dataset.add_frames(cols, ep.frames, gamma.tolist(), 0, ep.seed)
        new = Dataset.from_rows(cols, scenarios=[self.cfg.name])
        old = Dataset.load(self.out) if self.out.exists() else None
        merged = new if old is None else Dataset.merge([old, new])
        record = {
            "episode": int(merged.episode.max()),
            "scenario": self.cfg.name,
            "seed": ep.seed,
            "event": event,
            "frames": len(ep.frames),
            "negative": int(np.sum(gamma < 0)),
        }
        old_meta = old.meta if old is not None else {"source": "teleop"}
        meta: dict[str, Any] = {
            "source": "teleop",
            "command": self.command,
            "negative_window_s": NEGATIVE_WINDOW,
            "teleop_episodes": [*old_meta.get("teleop_episodes", []), record],
        }
        if old_meta.get("source") != "teleop":
            meta["source"] = "merge"
            parts = list(old_meta.get("parts", [old_meta.get("source", "?")]))
            meta["parts"] = parts if "teleop" in parts else [*parts, "teleop"]
        dataclasses.replace(merged, meta=meta).save(self.out)

    # ------------------------------------------------------------------ the loop
    def _poll(self) -> list[str]:
        """Key names of the pending pygame events, in order (closing the window is ESC)."""
        pg = self._pg
        keys: list[str] = []
        for event in pg.event.get():
            if event.type == pg.QUIT:
                keys.append("escape")
            elif event.type == pg.KEYDOWN and event.key in self._keymap:
                keys.append(self._keymap[event.key])
        return keys

    def handle_key(self, key: str) -> None:
        """Apply one key (by name); R and ESC act on the session at once."""
        if self.done:
            return
        action = self.controller.press(key)
        if action == "restart":
            self._finish_episode("restart")
            if not self.done:
                self._episode = self._start_episode()
        elif action == "quit":
            self._finish_episode("quit")
            self.done = True

    def step(self) -> str | None:
        """Record a frame, apply the current command for one control period; return the
        episode's end event (the next episode is started) or ``None``."""
        if self.done:
            return None
        ep = self._episode
        info = self._run.info
        ep.frames.append(
            {
                "step": len(ep.frames),
                "time": info["time"],
                "obs": self._run.obs,
                "action": self.controller.command,
                "pose": info["robot_pose"],
                "span": self.controller.span_open,
            }
        )
        self._run.step()
        pose = self._run.info["robot_pose"]
        ep.trail.append((float(pose[0]), float(pose[1])))
        event = self._run.event
        if event is not None:
            self._finish_episode(str(event))
            if not self.done:
                self._episode = self._start_episode()
        return None if event is None else str(event)

    def tick(self) -> bool:
        """Process pending events, step once, redraw; ``False`` once the session is over."""
        for key in self._poll():
            self.handle_key(key)
        if not self.done:
            self.step()
        if self.done:
            return False
        self.render()
        if self.realtime:
            self._clock.tick(1.0 / self.dt)  # the scenario's control rate
        return True

    def run(self) -> dict[str, Any]:
        """Tick until ESC, window close or ``max_episodes``; return :meth:`summary`."""
        try:
            while self.tick():
                pass
        finally:
            self.close()
        return self.summary()

    def close(self) -> None:
        """Save the unfinished episode (as ``"quit"``) and close the window. Idempotent."""
        if not self.done:
            self._finish_episode("quit")
            self.done = True
        if self._screen is not None:
            self._screen = None
            self._pg.display.quit()

    def summary(self) -> dict[str, Any]:
        """What this session saved, and the whole output file's summary."""
        return {
            "out": str(self.out),
            "scenario": self.cfg.name,
            "episodes": self.episodes_saved,
            "frames": self.frames_saved,
            "negative": self.negatives_saved,
            "events": list(self.events),
            "file": Dataset.load(self.out).summary() if self.out.exists() else None,
        }

    # ------------------------------------------------------------------ drawing
    def _say(self, text: str) -> None:
        self.message, self._message_ticks = text, MESSAGE_TICKS

    def status_line(self) -> str:
        """The text under the scene: command, time, episode count and the NEGATIVE marker."""
        c = self.controller
        mark = ""
        if c.negative:
            mark = "   NEGATIVE (episode)"
        elif c.span_open:
            mark = "   NEGATIVE (span)"
        return (
            f"v {c.v:.1f} m/s   ω {c.omega:+.2f} rad/s   t {self.time:4.1f} s   "
            f"episode {self.episodes_started}   saved {self.episodes_saved}{mark}"
        )

    def render(self) -> None:
        """Draw the current state and the status text into the window."""
        from pioneer.viz.frames import render_frame

        pg = self._pg
        trail = np.asarray(self._episode.trail, dtype=np.float64).reshape(-1, 2)
        img = render_frame(self.env.world, self.env.state, size=self.window_size, trail=trail)
        h, w = img.shape[:2]
        size = (max(w, MIN_WIDTH), h + STATUS_HEIGHT)
        if self._screen is None or self._screen.get_size() != size:
            self._screen = pg.display.set_mode(size)
            pg.display.set_caption(f"pioneer teleop · {self.cfg.name} · {self.out.name}")
        screen = self._screen
        screen.fill((255, 255, 255))
        screen.blit(pg.image.frombuffer(img.tobytes(), (w, h), "RGB"), ((size[0] - w) // 2, 0))
        pg.draw.line(screen, (180, 180, 180), (0, h), (size[0], h))
        red = self.controller.marking_negative
        lines = [(self.status_line(), (200, 0, 0) if red else (0, 0, 0))]
        if self._message_ticks > 0:
            self._message_ticks -= 1
            lines.append((self.message, (0, 90, 160)))
        else:
            lines.append(("UP/DOWN speed   LEFT/RIGHT turn   SPACE stop", (90, 90, 90)))
        lines.append(("N negative episode   B negative span   R restart   ESC quit", (90, 90, 90)))
        for i, (text, colour) in enumerate(lines):
            screen.blit(self._font.render(text, True, colour), (8, h + 6 + 20 * i))
        pg.display.flip()

    def screenshot(self, path: str | os.PathLike[str]) -> None:
        """Save the window as an image (PNG by extension)."""
        if self._screen is None:
            raise ConfigError(expect("screenshot", "an open window", None, "call before close()"))
        with atomic_path(path) as tmp:
            self._pg.image.save(self._screen, os.fspath(tmp))
