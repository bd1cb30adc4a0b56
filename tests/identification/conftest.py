"""Session fixtures: regressors of rx90 and lwr4 at random states (numeric Newton-Euler, slow,
computed once), with plausible random parameters and a payload with sizeable first moments.

The identification tests make many small LAPACK calls; on the shared 2-core machine a
multi-threaded OpenBLAS spends most of their time spinning (4x slower than one thread). The
package-scoped fixture below runs these tests with one BLAS thread and restores the previous
setting afterwards (a no-op when no OpenBLAS is found).
"""
import ctypes

import pytest

from .simdata import make_robot_sim

#: payload of the RX-90 tests (7.025 kg as Table 2, with sizeable MX/MY/MZ so that the wrist
#: joints feel it) and of the LWR4 tests (4.6136 kg, Sec. IV-B)
RX90_PAYLOAD = dict(payload_mass=7.025, payload_com=(0.10, -0.08, 0.14))
LWR4_PAYLOAD = dict(payload_mass=4.6136, payload_com=(0.09, -0.10, 0.15))


def _openblas_thread_controls():
    try:
        with open("/proc/self/maps") as f:
            paths = {line.split()[-1] for line in f if "openblas" in line.lower() and ".so" in line}
    except OSError:
        return []
    out = []
    for p in sorted(paths):
        try:
            lib = ctypes.CDLL(p)
        except OSError:
            continue
        for suffix in ("", "64_", "_64"):
            for prefix in ("openblas", "scipy_openblas"):
                get = getattr(lib, f"{prefix}_get_num_threads{suffix}", None)
                set_ = getattr(lib, f"{prefix}_set_num_threads{suffix}", None)
                if get is not None and set_ is not None:
                    out.append((get, set_))
    return out


@pytest.fixture(scope="package", autouse=True)
def single_blas_thread():
    controls = _openblas_thread_controls()
    before = [get() for get, _ in controls]
    for _, set_ in controls:
        set_(1)
    yield
    for (_, set_), n in zip(controls, before):
        set_(n)


@pytest.fixture(scope="session")
def rx90_sim():
    return make_robot_sim("rx90", 400, 400, seed=11, **RX90_PAYLOAD)


@pytest.fixture(scope="session")
def lwr4_sim():
    return make_robot_sim("lwr4", 400, 400, seed=12, **LWR4_PAYLOAD)
