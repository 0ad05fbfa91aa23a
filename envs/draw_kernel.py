"""The scenario's per-window draws (:func:`envs.scenario.draw_episodes`) compiled and run over the windows in
parallel, the same numbers as numpy's ``Generator`` calls to the bit.

Window ``i`` owns a numpy ``Generator``; numpy draws its numbers with two calls,
``rng.random(out=u[i])`` (each number the bit generator's ``next_double``) and
``rng.standard_normal(out=noise[i])`` (numpy's ziggurat, ``random_standard_normal`` of numpy's
``distributions.c``, on the bit generator's ``next_uint64`` and ``next_double``). Here each window's draws
call the same C functions of numpy's bit generator (the function pointers of its ``bitgen_t``, reached
through ``bit_generator.capsule``) on its state in place, and the ziggurat is numba's port of numpy's
(``numba.np.random.distributions.random_standard_normal``, the code behind numba's own
``Generator.standard_normal``): no copy of either algorithm here. After the draws each ``Generator`` is in
the state numpy's two calls leave it in (the state lives in the bit generator's C struct and is advanced
there), so the streams go on as before. ``tests/test_draw_kernel.py`` checks the numbers and the states
against numpy's calls (many seeds, the ziggurat's tail and wedge branches hit).

Windows are independent (one generator each), so the draws run in ``n_chunks`` contiguous chunks in
parallel (``prange``; ``n_chunks = 1``: on the calling thread); the numbers do not depend on the chunks.

Imported only when the vector env draws (numba is not imported by ``import envs``).
"""

from __future__ import annotations

import ctypes
import operator

import numpy as np
from llvmlite import ir
from numba import njit, prange, types
from numba.core import cgutils
from numba.extending import intrinsic
from numba.np.random.distributions import random_standard_normal
from numba.np.random.generator_core import next_double

from .chunked import run_chunks

__all__ = ["bitgen_addresses", "compiled_draws_agree", "Draws", "draw", "draw_rows"]

_BITGEN = types.NumPyRandomBitGeneratorType("bit_generator")
_CAPSULE_POINTER = ctypes.pythonapi.PyCapsule_GetPointer
_CAPSULE_POINTER.restype = ctypes.c_void_p
_CAPSULE_POINTER.argtypes = [ctypes.py_object, ctypes.c_char_p]


def bitgen_addresses(rngs) -> np.ndarray | None:
    """The address of each generator's ``bitgen_t`` (numpy's C struct: state, ``next_uint64``,
    ``next_uint32``, ``next_double``), or None when one of ``rngs`` is not a numpy ``Generator`` (the caller
    then draws with numpy). Valid while their bit generators live and are not replaced."""
    out = np.empty(len(rngs), dtype=np.uintp)
    for i, rng in enumerate(rngs):
        if type(rng) is not np.random.Generator:
            return None
        out[i] = _CAPSULE_POINTER(rng.bit_generator.capsule, b"BitGenerator")
    return out


class Draws:
    """The draws of :func:`envs.scenario.draw_episodes` (its ``fill``) by :func:`draw_rows`: ``draws(rngs, u,
    noise, n_chunks)`` returns False (nothing drawn: the caller draws with numpy's calls) when one of ``rngs``
    is not a numpy ``Generator``, or when this process's numpy / numba do not give numpy's numbers
    (:func:`compiled_draws_agree`, checked once per process).

    The addresses of the last list of generators are kept with their **bit generators** (held here, so they
    stay alive; compared by identity at each call, so a generator re-initialised with another bit generator
    or a new list is looked up again) and reused. The addresses are never copied: a copied or pickled
    ``Draws`` (``copy.deepcopy`` / ``pickle`` of an env) starts empty and looks its generators up anew. A list
    that holds one generator twice is drawn on one thread, in order (numpy's calls draw from it one window
    after the other). Like numpy's own calls without their lock: a sub-env's generator must not be drawn from
    by another Python thread meanwhile."""

    def __init__(self):
        self._bgs, self._addr, self._shared = [], None, False

    def __getstate__(self):
        return {}   # addresses are this process's and these objects': never carried to a copy

    def __setstate__(self, state):
        self.__init__()

    def __call__(self, rngs, u, noise, n_chunks, scale=1.0) -> bool:
        if not compiled_draws_agree():
            return False
        if not set(map(type, rngs)) <= _GENERATOR:   # (C-level loops: faster than a generator expression)
            return False
        bgs = list(map(_BIT_GENERATOR, rngs))
        # compared by identity with the last ones (held, so no other object takes their place; a C-level loop)
        if len(bgs) != len(self._bgs) or not all(map(operator.is_, bgs, self._bgs)):
            self._bgs, self._addr = bgs, bitgen_addresses(rngs)
            self._shared = self._addr is not None and len(np.unique(self._addr)) < len(self._addr)
        if self._addr is None:
            return False
        draw(self._addr, u, noise, 1 if self._shared else n_chunks, scale)
        return True


_BIT_GENERATOR = operator.attrgetter("bit_generator")
_GENERATOR = {np.random.Generator}
_AGREE: list = []


def compiled_draws_agree() -> bool:
    """Whether :func:`draw_rows` gives numpy's numbers and end states to the bit in this process (numba's
    ziggurat is a port of numpy's, and both are private code that a release could change): checked once on
    throwaway generators (2 x 2,000 normals and 12 uniforms, the ziggurat's wedge branch hit), False ->
    the vector env draws with numpy's calls."""
    if not _AGREE:
        seeds = (12345, 2024)
        ours = [np.random.default_rng(s) for s in seeds]
        ref = [np.random.default_rng(s) for s in seeds]
        u, noise = np.empty((2, 12)), np.empty((2, 2000))
        draw(bitgen_addresses(ours), u, noise, 1)
        ru, rn = np.empty_like(u), np.empty_like(noise)
        for i, g in enumerate(ref):
            g.random(out=ru[i])
            g.standard_normal(out=rn[i])
        _AGREE.append(u.tobytes() == ru.tobytes() and noise.tobytes() == rn.tobytes()
                      and all(a.bit_generator.state == b.bit_generator.state for a, b in zip(ours, ref)))
    return _AGREE[0]


@intrinsic
def _bitgen_at(typingctx, addr):
    """numba's bit-generator value (the struct its ``Generator`` support unboxes: the state and numpy's
    function pointers) read from the ``bitgen_t`` at address ``addr`` (no Python object behind it)."""
    sig = _BITGEN(types.uintp)

    def codegen(context, builder, sig, args):
        ll_uintp = context.get_value_type(types.uintp)
        fields = builder.inttoptr(args[0], ir.PointerType(ll_uintp))

        def field(k):
            return builder.load(builder.gep(fields, [ir.Constant(ir.IntType(32), k)]))

        bg = cgutils.create_struct_proxy(_BITGEN)(context, builder)   # zero-filled: no parent object
        state = field(0)
        bg.state_address, bg.state = state, state
        bg.fnptr_next_uint64, bg.fnptr_next_uint32, bg.fnptr_next_double = field(1), field(2), field(3)
        return bg._getvalue()

    return sig, codegen


#: windows drawn per block: their normals go to ``noise`` a block at a time, so that a transposed view (a store
#: (T, n) step-major) is written a run of _BLOCK values per step instead of one value per cache line
_BLOCK = 16


@njit(cache=True)
def _draw_rows(lo, hi, addr, u, noise, scale):
    buf = np.empty((_BLOCK, noise.shape[1]))
    for b0 in range(lo, hi, _BLOCK):
        b1 = min(b0 + _BLOCK, hi)
        for i in range(b0, b1):
            bg = _bitgen_at(addr[i])
            for k in range(u.shape[1]):    # rng.random(out=u[i])
                u[i, k] = next_double(bg)
            for t in range(noise.shape[1]):   # rng.standard_normal(out=noise[i])
                buf[i - b0, t] = random_standard_normal(bg)
        for t in range(noise.shape[1]):
            for i in range(b0, b1):
                noise[i, t] = buf[i - b0, t] * scale   # (the store's noise: numpy's normal times the scale)


@njit(cache=True, parallel=True)
def draw_rows(addr, u, noise, scale, n_chunks):
    """Window ``i``'s uniform numbers into ``u[i]`` and its standard normals times ``scale`` into ``noise[i]``
    (``scale = 1.0``: the normals themselves, ``x * 1.0`` is ``x``), drawn from the generator whose ``bitgen_t`` is
    at ``addr[i]`` (:func:`bitgen_addresses`), in ``n_chunks`` chunks of windows run in parallel (one chunk: the
    same numbers; :func:`draw` then calls the serial loop itself)."""
    n, k = u.shape[0], max(n_chunks, 1)
    for c in prange(k):
        _draw_rows(c * n // k, (c + 1) * n // k, addr, u, noise, scale)


def draw(addr, u, noise, n_chunks, scale=1.0) -> None:
    """:func:`draw_rows` over ``n_chunks`` chunks of windows (:func:`envs.chunked.run_chunks`: one chunk calls the
    serial loop itself, on the calling thread)."""
    run_chunks(_draw_rows, draw_rows, u.shape[0], n_chunks, addr, u, noise, float(scale))
