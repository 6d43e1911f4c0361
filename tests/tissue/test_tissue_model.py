"""The tissue model as data: frozen, read-only arrays, and one memo per model that keeps what
the solvers and the integrators derive from it (each thing built once, a copy has its own)."""

import dataclasses
import gc
import threading
import weakref

import numpy as np
import pytest

from myoface.tissue import make_lattice, relax, rest_state, step_rk2
from myoface.tissue import rk2 as rk2_mod
from myoface.tissue.rk2 import rk2_integrator, run_rk2


def _lattice():
    """One prism, its lower triangle kinematic, its upper one held by nine springs."""
    pos = np.array([[0, 0, 0], [4, 0, 0], [0, 4, 0], [0, 0, 3], [4, 0, 3], [0, 4, 3]], float)
    springs = [[3, 4], [4, 5], [5, 3], [0, 3], [1, 4], [2, 5], [0, 4], [1, 5], [2, 3]]
    kin = np.array([True, True, True, False, False, False])
    m = make_lattice(
        pos,
        springs,
        mass=0.02,
        damping=0.5,
        kinematic=kin,
        elements=[[0, 1, 2, 3, 4, 5]],
        volume_weight=5.0,
    )
    return pos, m


def test_the_model_is_frozen_and_its_arrays_read_only(default_tissue):
    m = default_tissue
    with pytest.raises(dataclasses.FrozenInstanceError):
        m.mass = np.ones(m.n_nodes)
    for name in ("rest_positions", "mass", "damping", "kinematic", "spring_i", "materials"):
        with pytest.raises(ValueError, match="read-only"):
            getattr(m, name)[0] = 0
    with pytest.raises(ValueError, match="read-only"):
        m.kinematic_index[0] = 0


def test_the_callers_arrays_stay_theirs():
    pos, m = _lattice()
    assert pos.flags.writeable  # the model holds a read-only view, not the caller's flags
    assert not m.rest_positions.flags.writeable
    np.testing.assert_array_equal(m.rest_positions, pos)


def test_a_copy_of_the_model_has_a_memo_of_its_own(default_tissue):
    m = default_tissue
    m2 = m.with_kinematic(m.layer_nodes("fascia")[:5])
    assert m2.memo("k", lambda: "copy") == "copy"
    assert m.memo("k", lambda: "original") == "original"
    assert rk2_integrator(m) is rk2_integrator(m)
    assert rk2_integrator(m2) is not rk2_integrator(m)
    assert len(m2.kinematic_index) == len(m.kinematic_index) + 5


def test_the_memo_computes_each_key_once_across_threads():
    _, m = _lattice()
    calls = []
    barrier = threading.Barrier(4)

    def compute():
        calls.append(1)
        return object()

    got = []

    def work():
        barrier.wait()
        got.append(m.memo("shared", compute))

    threads = [threading.Thread(target=work) for _ in range(4)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    assert len(calls) == 1 and all(g is got[0] for g in got)


def test_a_failed_computation_is_not_kept():
    _, m = _lattice()

    def fails():
        raise RuntimeError("no")

    with pytest.raises(RuntimeError):
        m.memo("key", fails)
    assert m.memo("key", lambda: 3) == 3


def test_the_rk2_integrator_keeps_its_plans():
    _, m = _lattice()
    integ = rk2_integrator(m)
    assert integ.model is m
    assert integ.plan(1) is integ.plan(1)
    assert integ.plan(2) is not integ.plan(1)
    with pytest.raises(ValueError, match="n_blocks"):
        integ.plan(0)


def test_a_model_and_what_it_keeps_go_when_it_is_dropped():
    """Nothing refers to a model from outside it (no module-level table keyed on models, no
    reference cycle through its memo): it is freed as soon as its last user lets it go."""
    gc.disable()  # freed by reference counting alone, not by the cycle collector
    try:
        _, m = _lattice()
        tg = m.rest_positions[m.kinematic_index] + [0.3, 0.0, 0.2]
        s = step_rk2(m, rest_state(m), tg, n_steps=3)
        relax(m, s, tg, method="lbfgs")
        relax(m, s, tg)
        x, v = s.x.copy(), s.v.copy()
        run_rk2(m, x, v, 5, m.stable_dt, n_blocks=2)
        integ = rk2_integrator(m)
        ref = weakref.ref(m)
        del m
        assert ref() is None
        with pytest.raises(ReferenceError):
            integ.plan(3)  # a plan not built yet needs the model
    finally:
        gc.enable()


def test_the_spin_wait_takes_the_x86_pause_only_on_x86(monkeypatch):
    """The team's spin-wait emits x86's ``pause`` where the machine is x86, nothing elsewhere
    (LLVM has no x86 intrinsic on another machine: the kernel would not compile)."""
    from numba import njit

    for x86 in (False, True) if rk2_mod.X86 else (False,):
        monkeypatch.setattr(rk2_mod, "X86", x86)

        @njit
        def spin():
            rk2_mod._spin_pause()

        spin()
        ir = "".join(spin.inspect_llvm().values())
        assert ("llvm.x86.sse2.pause" in ir) is x86
