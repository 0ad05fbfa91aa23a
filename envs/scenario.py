"""Scenarios of a charging window (domain randomisation and evaluation sets) and the seeded
command (reference) generator.

A :class:`Scenario` is a frozen set of ranges; every episode draws its own values from them with
the environment's ``np_random`` in a fixed order (:func:`draw_episode`), so an episode is a pure
function of (scenario, seed).

=============  ============================================================================
name           what varies
=============  ============================================================================
nominal        Table I link at the nominal hover pose (no wind), SoC 0.5, commands 2..7 A
lm_mismatch    true Lm scaled by 0.8..1.25 against the Table I value every policy assumes
windy          2..4 m/s wind with gusts: hover pose error and tilt (hence Lm) vary between windows
battery        battery SoC 0.1..0.95 (battery voltage ~ 25..33 V instead of ~30 V)
random         all of the above at once (the training distribution)
lm_high        true Lm 1.3..1.5 x: outside the training range (held out in ``compare``)
lm_drift       Lm falling over the window by 5..20 % (a drone leaving the pad), linear in time
lm_drift_fast  held out: Lm falling by 20..35 % over the window
sense_delay    the current measurements (I2, battery and SBAR output current) reach the
               policy 1..2 control periods late (drawn per window)
sense_delay_long  held out: 3..4 control periods late
battery_low    battery far from nominal: SoC 0.02..0.06 (VL ~ 25.4..28.1 V)
battery_empty  held out: SoC 0..0.02 (VL ~ 21..25 V; the ripple table extrapolated below 27 V)
detuned        C1 and C2 each off resonance by -5..+5 % (drawn per window; complex envelope, envs.detuned)
detuned_wide   held out: C1 and C2 each off by -8..+8 %
=============  ============================================================================

The model-is-wrong scenarios (``lm_drift``, ``sense_delay``, ``battery_low``; each with a held-out
variant) break what the model-based policies assume (a constant Table I Lm, a measurement of the
present, a battery near 30 V) inside a window, where an adaptive or learned policy could win.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from itertools import accumulate

import numpy as np

from mission_sim.validation import Range, check_number, real_number, shown

__all__ = ["Scenario", "SCENARIOS", "HELD_OUT", "get_scenario", "EpisodeDraw", "draw_episode", "draw_episodes", "stack_draws",
           "command_profile", "scenario_from_options", "Draw", "DRAWS", "register_scenario", "ScenarioPart", "Window"]


class Draw:
    """A scenario part: the uniform numbers it draws for every window and the named window fields it
    sets from them (the fields of :class:`EpisodeDraw`). :data:`DRAWS` are every scenario's; a scenario's
    ``parts`` are its own (each carries its own ranges), drawn after them. A subclass gives

    * ``ranges(scn)`` - the uniform ranges ``(lo, hi)`` it draws, in order (a point ``lo == hi`` is not
      drawn: it costs no random number, so adding a draw leaves the windows of other scenarios unchanged);
    * ``apply(scn, cols, win)`` - sets fields of the dict ``win`` by name from ``cols`` (one array (n,)
      per range, the draws of the n windows), after the draws before it (it may overwrite their fields).
    """

    def ranges(self, scn) -> tuple:
        raise NotImplementedError

    def apply(self, scn, cols, win: dict) -> None:
        raise NotImplementedError


@dataclass(frozen=True)
class Scenario:
    """Ranges an episode is drawn from (uniform unless stated). Units in the names.

    lm_scale : multiplier on the coupling model's Lm (the truth); policies keep assuming Table I
    wind_speed_m_s : mean wind speed; sets the hover pose error (:mod:`envs.plant`)
    soc : initial state of charge
    cmd_a : charge command levels before the stop [A] (RM delivers ~7 A at Table I)
    t_change_s : time of the one command change while charging [s]
    t_stop_s : time the command drops to 0 (battery full / departure): RM -> SM [s]
    i2_noise_a : standard deviation of the I2 envelope sensor noise [A]
    hover_power_w : propulsion power drawn from the battery while hovering [W]; None = the default
        drone's momentum-theory hover power (:func:`envs.plant.default_hover_power_w`, ~99 W)
    lm_drift : relative change of the true Lm over the window (``Lm(t) = Lm_0(t) (1 + drift t / T_window)``;
        negative: the coupling falls, a drone leaving the pad)
    sense_delay_steps : the current measurements of the observation (I2, battery current, SBAR output
        current) are this many control periods old (integer, drawn uniformly per window)
    c_detune : relative error of C1 and of C2 (each drawn) against the resonant value 1/(w^2 L)
    parts : further draws of this scenario, each a :class:`Draw` carrying its own ranges (drawn after the
        built-in :data:`DRAWS`, in order): a new kind of scenario is one new ``Draw``, see docs/envs.md
    """

    name: str = "custom"
    lm_scale: tuple[float, float] = (1.0, 1.0)
    wind_speed_m_s: tuple[float, float] = (0.0, 0.0)
    soc: tuple[float, float] = (0.5, 0.5)
    cmd_a: tuple[float, float] = (2.0, 7.0)
    t_change_s: tuple[float, float] = (3e-3, 8e-3)
    t_stop_s: tuple[float, float] = (10e-3, 16e-3)
    i2_noise_a: float = 0.1
    hover_power_w: float | None = None
    lm_drift: tuple[float, float] = (0.0, 0.0)
    sense_delay_steps: tuple[int, int] = (0, 0)
    c_detune: tuple[float, float] = (0.0, 0.0)
    parts: tuple = ()

    def __post_init__(self):
        limits = {"lm_scale": (0.3, 2.0), "wind_speed_m_s": (0.0, 30.0), "soc": (0.0, 1.0),
                  "cmd_a": (0.0, 20.0), "t_change_s": (0.0, 1.0), "t_stop_s": (0.0, 1.0), "lm_drift": (-0.6, 0.6),
                  "sense_delay_steps": (0, 20), "c_detune": (-0.3, 0.3)}
        for f in fields(self):
            if f.name not in limits:
                continue
            lo, hi = _pair(f.name, getattr(self, f.name))
            vlo, vhi = limits[f.name]
            if not (vlo <= lo <= hi <= vhi):
                raise ValueError(f"scenario {f.name}=({lo}, {hi}) is invalid; valid range: "
                                 f"{vlo} <= low <= high <= {vhi}")
            if f.name == "sense_delay_steps":
                if lo != int(lo) or hi != int(hi):
                    raise ValueError(f"scenario sense_delay_steps=({lo}, {hi}) is invalid; valid: integers 0..20")
                lo, hi = int(lo), int(hi)
            object.__setattr__(self, f.name, (lo, hi))
        check_number("i2_noise_a", self.i2_noise_a, _NONNEGATIVE)   # (a string: one line, not numpy's TypeError)
        if self.hover_power_w is not None:
            check_number("hover_power_w", self.hover_power_w, _NONNEGATIVE)
        object.__setattr__(self, "parts", tuple(self.parts))
        for part in self.parts:
            if not isinstance(part, Draw):
                raise ValueError(f"scenario part {part!r} is invalid; valid: envs.scenario.Draw instances")

    @property
    def load_power_w(self) -> float:
        from .plant import default_hover_power_w
        return default_hover_power_w() if self.hover_power_w is None else float(self.hover_power_w)

    def with_(self, **changes) -> "Scenario":
        return replace(self, **changes)


_NONNEGATIVE = Range(0, float("inf"), hi_open=True)


def _pair(name: str, value) -> tuple:
    """A scenario range as ``(low, high)`` floats: a pair, or one number for a point range (``soc=0.5`` is
    ``soc=(0.5, 0.5)``, which draws nothing); anything else one line naming it (real numbers as
    :func:`mission_sim.validation.real_number` takes them: not a string such as YAML's ``"1e-4"``)."""
    v = real_number(value)
    if v is not None:
        return v, v
    try:
        lo, hi = (real_number(x) for x in value)
    except (TypeError, ValueError):   # not iterable, or not two items
        lo = hi = None
    if lo is None or hi is None:
        raise ValueError(f"scenario {name}={shown(value)} is invalid; valid: a number or a (low, high) pair")
    return lo, hi


SCENARIOS: dict[str, Scenario] = {
    "nominal": Scenario("nominal"),
    "lm_mismatch": Scenario("lm_mismatch", lm_scale=(0.8, 1.25)),
    "windy": Scenario("windy", wind_speed_m_s=(2.0, 4.0)),
    "battery": Scenario("battery", soc=(0.1, 0.95)),
    "random": Scenario("random", lm_scale=(0.8, 1.25), wind_speed_m_s=(0.0, 4.0), soc=(0.1, 0.95)),
    "lm_high": Scenario("lm_high", lm_scale=(1.3, 1.5)),
    "lm_drift": Scenario("lm_drift", lm_drift=(-0.2, -0.05)),
    "lm_drift_fast": Scenario("lm_drift_fast", lm_drift=(-0.35, -0.2)),
    "sense_delay": Scenario("sense_delay", sense_delay_steps=(1, 2)),
    "sense_delay_long": Scenario("sense_delay_long", sense_delay_steps=(3, 4)),
    "battery_low": Scenario("battery_low", soc=(0.02, 0.06)),
    "battery_empty": Scenario("battery_empty", soc=(0.0, 0.02)),
    "detuned": Scenario("detuned", c_detune=(-0.05, 0.05)),
    "detuned_wide": Scenario("detuned_wide", c_detune=(-0.08, 0.08)),
}
#: held-out variant of each model-is-wrong scenario (not in the range of its default one)
HELD_OUT = {"lm_drift": "lm_drift_fast", "sense_delay": "sense_delay_long", "battery_low": "battery_empty",
            "detuned": "detuned_wide"}
#: the built-in scenarios' names: :func:`register_scenario` does not replace them (``compare``'s rows by these names
#: are the documented windows)
BUILT_IN = tuple(SCENARIOS)


def scenario_from_options(options, default: Scenario) -> Scenario:
    """The scenario of ``reset(options=...)``: ``options["scenario"]`` or ``default``; other keys are errors."""
    if not options:
        return default
    if not isinstance(options, Mapping):   # a string was iterated: "reset option 'w' is invalid"
        raise ValueError(f"options={options!r} is invalid; valid: None or a dict {{'scenario': NAME, a Scenario or a "
                         "dict of its fields}")
    bad = set(options) - {"scenario"}
    if bad:
        raise ValueError(f"reset option {sorted(bad)[0]!r} is invalid; valid keys: 'scenario'")
    return get_scenario(options["scenario"])


def get_scenario(scenario) -> Scenario:
    """A :class:`Scenario` from a name in :data:`SCENARIOS`, a Scenario, or a dict of fields."""
    if isinstance(scenario, Scenario):
        return scenario
    if isinstance(scenario, str):
        if scenario not in SCENARIOS:
            raise ValueError(f"scenario={scenario!r} is invalid; valid values: {', '.join(SCENARIOS)}")
        return SCENARIOS[scenario]
    if isinstance(scenario, dict):
        base = get_scenario(scenario.get("base", "nominal"))
        known = {f.name for f in fields(Scenario)}
        bad = set(scenario) - known - {"base"}
        if bad:
            raise ValueError(f"scenario key {sorted(bad)[0]!r} is invalid; valid keys: {', '.join(sorted(known))}, "
                             "base (the scenario the others change; default nominal)")
        return base.with_(**{k: v for k, v in scenario.items() if k != "base"})
    raise ValueError(f"scenario={scenario!r} is invalid; give a name ({', '.join(SCENARIOS)}), a Scenario or a dict")


@dataclass(frozen=True)
class EpisodeDraw:
    """The random numbers of one episode (drawn in this order from the env's ``np_random``), or of
    a batch of episodes (every field an array with the episodes along axis 0: :func:`draw_episodes`)."""

    soc0: float
    lm_scale: float
    wind_speed_m_s: float
    record_u: float          # start of the window in the wind level's weather record, [0, 1)
    cmd0_a: float
    cmd1_a: float
    t_change_s: float
    t_stop_s: float
    noise: np.ndarray | None  # (n_steps,) standard normals for the I2 sensor (None: drawn into a store, Window)
    lm_drift: float = 0.0    # relative Lm change over the window
    sense_delay: float = 0.0  # measurement delay [control periods] (integer valued)
    c1_detune: float = 0.0   # relative C1 error
    c2_detune: float = 0.0   # relative C2 error

    @property
    def n(self) -> int:
        """Episodes in a batched draw (1 for a single one)."""
        return int(np.size(self.soc0))


#: the uniformly drawn fields of :func:`draw_episode`, in drawing order (record_u is always drawn, on [0, 1))
_RANGED = ("soc", "lm_scale", "wind_speed_m_s", None, "cmd_a", "cmd_a", "t_change_s", "t_stop_s", "lm_drift",
           "sense_delay_steps", "c_detune", "c_detune")


def _range(scn: Scenario, f):
    """The uniform range of a field of :data:`_RANGED` (an integer range lo..hi is drawn on [lo, hi + 1) and floored)."""
    if f is None:
        return (0.0, 1.0)
    lo, hi = getattr(scn, f)
    return (float(lo), float(hi) + 1.0) if f == "sense_delay_steps" and hi > lo else (float(lo), float(hi))


def _delay(x, scn: Scenario):
    lo, hi = scn.sense_delay_steps
    return np.minimum(np.floor(x), hi) if hi > lo else x


def _u(rng, lohi):
    lo, hi = lohi
    return float(rng.uniform(lo, hi)) if hi > lo else float(lo)


def draw_episode(rng: np.random.Generator, scn: Scenario, n_steps: int, n_slow: int) -> EpisodeDraw:
    """Draw one episode's random numbers of the built-in draws with scalar generator calls (the reference
    :func:`draw_episodes` is tested against; a scenario's own ``parts`` are drawn by :func:`draw_episodes` only)."""
    return EpisodeDraw(
        soc0=_u(rng, scn.soc), lm_scale=_u(rng, scn.lm_scale), wind_speed_m_s=_u(rng, scn.wind_speed_m_s),
        record_u=float(rng.uniform()),
        cmd0_a=_u(rng, scn.cmd_a), cmd1_a=_u(rng, scn.cmd_a),
        t_change_s=_u(rng, scn.t_change_s), t_stop_s=_u(rng, scn.t_stop_s),
        lm_drift=_u(rng, scn.lm_drift), sense_delay=float(_delay(_u(rng, _range(scn, "sense_delay_steps")), scn)),
        c1_detune=_u(rng, scn.c_detune), c2_detune=_u(rng, scn.c_detune),
        noise=rng.standard_normal(n_steps),
    )


class _Field(Draw):
    """One window field drawn from one range of the scenario (``scenario_field``; None: [0, 1))."""

    def __init__(self, scenario_field, window_field: str):
        self.scenario_field, self.window_field = scenario_field, window_field

    def ranges(self, scn):
        return (_range(scn, self.scenario_field),)

    def apply(self, scn, cols, win):
        win[self.window_field] = cols[0]


class _Command(Draw):
    """The reference: two command levels [A], the time of the change and of the stop [s]."""

    def ranges(self, scn):
        return tuple(_range(scn, f) for f in ("cmd_a", "cmd_a", "t_change_s", "t_stop_s"))

    def apply(self, scn, cols, win):
        win["cmd0_a"], win["cmd1_a"], win["t_change_s"], win["t_stop_s"] = cols


class _SenseDelay(_Field):
    """The sensing delay [control periods]: an integer range drawn uniformly (floored)."""

    def apply(self, scn, cols, win):
        win[self.window_field] = _delay(cols[0], scn)


class _Detune(Draw):
    """Relative C1 and C2 errors, each drawn from ``c_detune``."""

    def ranges(self, scn):
        return (_range(scn, "c_detune"),) * 2

    def apply(self, scn, cols, win):
        win["c1_detune"], win["c2_detune"] = cols


#: the built-in draws of every scenario, in drawing order (the order of :func:`draw_episode`; a field whose
#: range is a point is not drawn, so a scenario's windows do not change when a draw is added after these)
DRAWS = (_Field("soc", "soc0"), _Field("lm_scale", "lm_scale"), _Field("wind_speed_m_s", "wind_speed_m_s"),
         _Field(None, "record_u"), _Command(), _Field("lm_drift", "lm_drift"),
         _SenseDelay("sense_delay_steps", "sense_delay"), _Detune())


def draw_episodes(rngs, scn: Scenario, n_steps: int, fill=None, noise=None, scale: float = 1.0) -> EpisodeDraw:
    """A batched :class:`EpisodeDraw`, episode ``i`` from generator ``rngs[i]``: the :data:`DRAWS` and then the
    scenario's own ``parts``, each filling its named fields (the same numbers as :func:`draw_episode` with each
    generator: ``uniform(lo, hi)`` is ``lo + (hi - lo) u`` of the generator's next double, so one ``random(k)``
    call gives the k scalar draws); two generator calls per episode and the rest on arrays. ``fill(rngs, u,
    noise, scale)``: draws the generators' numbers into ``u`` and ``noise`` (the normals times ``scale``) instead
    of those calls, the same numbers (the vector env's compiled draws, :mod:`envs.draw_kernel`), or returns False
    to leave them to the calls. ``noise``: the (n, n_steps) array the normals are drawn into (any strides: a
    store's transposed view), else a new one; ``scale``: its normals are multiplied by it (the sensor noise's
    standard deviation: one product per number, wherever it is taken)."""
    parts = DRAWS + scn.parts
    ranges = [part.ranges(scn) for part in parts]
    flat = [r for rs in ranges for r in rs]
    drawn = [i - 1 for i in accumulate(hi > lo for lo, hi in flat)]   # column in u of each drawn range
    n = len(rngs)
    u = np.empty((n, drawn[-1] + 1))
    noise = np.empty((n, n_steps)) if noise is None else noise
    if fill is None or not fill(rngs, u, noise, scale):
        rows = noise if noise.flags.c_contiguous else np.empty((n, n_steps))   # numpy's out: contiguous
        for i, rng in enumerate(rngs):  # each sub-environment owns its generator: one call per array
            rng.random(out=u[i])
            rng.standard_normal(out=rows[i])
        if rows is not noise or scale != 1.0:
            np.multiply(rows, scale, out=noise)
    cols = [lo + (hi - lo) * u[:, drawn[i]] if hi > lo else np.full(n, float(lo)) for i, (lo, hi) in enumerate(flat)]
    win, at = {}, 0
    for part, rs in zip(parts, ranges):
        part.apply(scn, cols[at:at + len(rs)], win)
        at += len(rs)
    return EpisodeDraw(noise=noise, **win)


def stack_draws(draws) -> EpisodeDraw:
    """One batched :class:`EpisodeDraw` from a list of single ones."""
    names = ("soc0", "lm_scale", "wind_speed_m_s", "record_u", "cmd0_a", "cmd1_a", "t_change_s", "t_stop_s",
             "lm_drift", "sense_delay", "c1_detune", "c2_detune")
    cols = {k: np.array([getattr(d, k) for d in draws], dtype=float) for k in names}
    return EpisodeDraw(**cols, noise=np.stack([d.noise for d in draws]))


def command_profile(draws, n_steps: int, dt_s: float, out=None, n_chunks: int = 1, compiled: bool = True) -> np.ndarray:
    """Charge command [A] per step, shape (n, n_steps + 1) for a batched draw (or a list of
    draws): cmd0 until t_change, cmd1 until t_stop, then 0 (stop charging -> short mode) to the
    end of the window; the transposed view of a step-major (n_steps + 1, n) array: ``out`` if given (any
    float array of that shape, written in place; the vector env passes its whole C-contiguous store), else a
    new one. The arithmetic is :func:`envs.command_kernel.command_rows` (compiled; ``n_chunks > 1``: over the
    steps in parallel, the same numbers; ``compiled=False``: its source uncompiled)."""
    from .command_kernel import fill_commands
    b = stack_draws(draws) if isinstance(draws, (list, tuple)) else draws
    tc, ts, c0, c1 = (np.ascontiguousarray(np.reshape(x, -1), dtype=float)
                      for x in (b.t_change_s, b.t_stop_s, b.cmd0_a, b.cmd1_a))
    if out is None:
        out = np.empty((n_steps + 1, tc.shape[0]))
    fill_commands(float(dt_s), tc, ts, c0, c1, out, n_chunks, compiled)
    return out.T


def register_scenario(scn: Scenario, held_out: Scenario | None = None) -> Scenario:
    """Add ``scn`` (and its held-out variant) to :data:`SCENARIOS` under its name, so ``scenario="name"``
    and ``reset(options={"scenario": "name"})`` find it; returns it."""
    for s in (scn, held_out):
        if s is None:
            continue
        if not isinstance(s, Scenario) or not s.name or s.name == "custom":
            raise ValueError(f"scenario={s!r} is invalid; valid: a Scenario with its own name")
        if s.name in BUILT_IN and s != SCENARIOS[s.name]:   # (it replaced "nominal" for the whole process, silently)
            raise ValueError(f"scenario name {s.name!r} is a built-in scenario's; valid: a name of your own (the "
                             f"built-in ones: {', '.join(BUILT_IN)})")
    for s in (scn, held_out):
        if s is not None:
            SCENARIOS[s.name] = s
    if held_out is not None:
        HELD_OUT[scn.name] = held_out.name
    return scn


@dataclass
class Window:
    """What the scenario part hands the other parts at a reset, for the ``n`` windows that start (named
    fields, arrays along the windows): the draws, the command (the reference) and the I2 sensor noise
    (views of the part's stores), the hover draw and the scenario. (``draw.noise`` is None at every reset: the
    normals are drawn times the noise's standard deviation, into the noise store when all windows start, else into
    a new array copied into its columns; ``noise_a`` has them.)"""

    draw: EpisodeDraw
    cmd_a: np.ndarray       # (n, T + 1) charge command per step [A]
    noise_a: np.ndarray     # (n, T) I2 sensor noise [A]
    load_w: np.ndarray      # (n,) hover power drawn from the battery [W]
    scenario: Scenario

    @property
    def n(self) -> int:
        return self.draw.n


class ScenarioPart:
    """The reference generator and scenario draws (gym-electric-motor's reference generator, with the
    episode's randomisation): at a reset, the scenario of the options, the draws of the windows that start
    (:func:`draw_episodes`: :data:`DRAWS` and the scenario's ``parts``), the command profile and the
    sensor noise written into the stores ``cmd`` (T + 1, n) and ``noise`` (T, n) (step-major, what the
    compiled step reads). Stateless between resets (``current``: the scenario of the windows started last)."""

    def __init__(self, default: Scenario, n_steps: int, dt_s: float, cmd: np.ndarray, noise: np.ndarray, fill=None,
                 chunks=None, compiled: bool = True):
        self.default = self.current = get_scenario(default)
        self.n_steps, self.dt_s = int(n_steps), float(dt_s)
        self.cmd, self.noise = cmd, noise
        self.fill = fill   # the draws' fill (draw_episodes' with the chunks last), None: the generators' own calls
        self.chunks = chunks   # () -> the parallel chunks of the draws and the command profile (threads set); None: one
        self.compiled = compiled   # False: the command profile's source uncompiled (tests)
        self._chunks = 1   # the current reset's chunks (:meth:`_fill_chunks`)

    def reset(self, rngs, idx, options=None) -> Window:
        """Windows ``idx`` (a slice for all, or indices of the stores' columns) start, drawn with ``rngs``
        (one generator each); ``options``: the ``reset`` options (``{"scenario": ...}``; None: the default scenario,
        as an autoreset)."""
        self.current = scenario_from_options(options, self.default)
        scn, T = self.current, self.n_steps
        full = isinstance(idx, slice)
        # the normals drawn times the noise's standard deviation; all windows (the usual autoreset): into the
        # noise store, and the command into its store, no temporaries
        chunks = self._chunks = 1 if self.chunks is None else self.chunks()   # (once: the draws' and the command's)
        fill = None if self.fill is None else self._fill_chunks
        draws = draw_episodes(rngs, scn, T, fill, noise=self.noise.T if full else None, scale=scn.i2_noise_a)
        n = draws.n
        cmd = command_profile(draws, T, self.dt_s, out=self.cmd if full else None, n_chunks=chunks,
                              compiled=self.compiled)
        noise = draws.noise
        draws = replace(draws, noise=None)   # (its normals are scaled: the window's noise_a)
        if not full:
            self.cmd[:, idx], self.noise[:, idx] = cmd.T, noise.T
        return Window(draws, cmd, noise, np.full(n, scn.load_power_w), scn)

    def _fill_chunks(self, rngs, u, noise, scale) -> bool:
        """:func:`draw_episodes`' ``fill``: the part's ``fill`` in the current reset's chunks (was a lambda built per reset)."""
        return self.fill(rngs, u, noise, scale, self._chunks)


def _env_scenario(env) -> Scenario:
    return env.parts.scenario.default


def _set_env_scenario(env, scenario) -> None:
    env.parts.scenario.default = get_scenario(scenario)


#: an env's ``scenario``: its scenario part's default, the scenario its resets without options, autoresets and
#: ``restart`` start; assigning it (SB3's ``set_attr("scenario", ...)``, gymnasium's ``set_attr``, a curriculum) sets
#: that default for every later start (a name, a :class:`Scenario` or a dict, as the constructor's: :func:`get_scenario`)
ENV_SCENARIO = property(_env_scenario, _set_env_scenario, doc="The scenario the env's resets without options start "
                        "(its scenario part's default); assignable: a name, a Scenario or a dict, as the constructor's.")
