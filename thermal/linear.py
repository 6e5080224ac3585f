"""Linear thermal networks C dT/dt = -K T + s + B u: the form the lumped and 1-D models hand to a DAE assembler.

C (diagonal capacities), K (conductance matrix, dense or scipy.sparse), s (constant sources, e.g. ambient
convection), B (input matrix for heat inputs / boundary temperatures u(t)). Energy is Σ C_i T_i; for a
closed network the column sums of K vanish except for losses to the surroundings, so the network conserves
heat exactly (tests/test_thermal_energy.py). Units: lumped models W, J/K; 1-D models per unit area.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import scipy.sparse as sps


def solve_ivp(*args, **kwargs):
    """scipy.integrate.solve_ivp, imported on first call (a fresh `mechsim run` need not load scipy.integrate)."""
    from scipy.integrate import solve_ivp as impl
    return impl(*args, **kwargs)


@dataclass(frozen=True)
class LinearThermalSystem:
    """C dT/dt = -K T + source + input_matrix @ u."""

    state_names: tuple[str, ...]
    capacity: np.ndarray
    conductance: np.ndarray | sps.spmatrix
    source: np.ndarray
    input_matrix: np.ndarray
    input_names: tuple[str, ...]

    def __post_init__(self):
        n = len(self.state_names)
        if self.capacity.shape != (n,) or self.source.shape != (n,) or self.conductance.shape != (n, n):
            raise ValueError("LinearThermalSystem: inconsistent shapes")
        if self.input_matrix.shape != (n, len(self.input_names)):
            raise ValueError("LinearThermalSystem: input_matrix must be (n_states, n_inputs)")
        if np.any(self.capacity <= 0):
            raise ValueError("LinearThermalSystem: capacities must be positive")

    @property
    def size(self) -> int:
        return len(self.state_names)

    def dense_conductance(self) -> np.ndarray:
        K = self.conductance
        return K.toarray() if sps.issparse(K) else np.asarray(K)

    def rhs(self, T, u) -> np.ndarray:
        """dT/dt for state T and input vector u."""
        return (-(self.conductance @ T) + self.source + self.input_matrix @ np.atleast_1d(u)) / self.capacity

    def jacobian(self):
        """d(dT/dt)/dT = -C^-1 K (sparse if K is sparse): constant, pass it as `jac` to implicit solvers."""
        if sps.issparse(self.conductance):
            return sps.csc_matrix(-sps.diags(1.0 / self.capacity) @ self.conductance)
        return -self.conductance / self.capacity[:, None]

    def energy(self, T, T_ref: float = 0.0) -> np.ndarray:
        """Stored heat Σ C_i (T_i - T_ref) (J, or J/m^2 for 1-D models); T may be (n,) or (n, n_times)."""
        return self.capacity @ (np.asarray(T) - T_ref)

    def steady_state(self, u) -> np.ndarray:
        """T with K T = s + B u (needs a loss to the surroundings: K non-singular)."""
        rhs = self.source + self.input_matrix @ np.atleast_1d(u)
        if sps.issparse(self.conductance):
            return sps.linalg.spsolve(sps.csc_matrix(self.conductance), rhs)
        return np.linalg.solve(self.dense_conductance(), rhs)

    def time_constants(self) -> np.ndarray:
        """Time constants 1/lambda of the modes, lambda = eigenvalues of C^-1 K, sorted longest first (inf for lambda = 0)."""
        c = np.sqrt(self.capacity)
        sym = self.dense_conductance() / c[:, None] / c[None, :]   # similar to C^-1 K, symmetric for a reciprocal network
        lam = np.linalg.eigvalsh(0.5 * (sym + sym.T))
        with np.errstate(divide="ignore"):
            return np.sort(np.where(lam > 0, 1.0 / np.where(lam > 0, lam, 1.0), np.inf))[::-1]

    def propagate(self, T0, u, times) -> np.ndarray:
        """Exact solution for constant u at the given times (from T0 at t = 0), via the matrix exponential of the
        augmented system [[-C^-1 K, C^-1(s + B u)], [0, 0]] (scipy.linalg.expm). Returns (len(times), n)."""
        n = self.size
        M = np.zeros((n + 1, n + 1))
        M[:n, :n] = -self.dense_conductance() / self.capacity[:, None]
        M[:n, n] = (self.source + self.input_matrix @ np.atleast_1d(u)) / self.capacity
        z0 = np.append(np.asarray(T0, dtype=float), 1.0)
        from scipy.linalg import expm
        return np.array([(expm(M * t) @ z0)[:n] for t in np.atleast_1d(times)])

    def integrate(self, t_span, T0, inputs: Callable[[float], np.ndarray], *, t_eval=None, method: str = "BDF",
                  rtol: float = 1e-8, atol: float = 1e-10, max_step: float = np.inf):
        """solve_ivp with the exact (sparse) Jacobian; `inputs(t)` returns u. Implicit methods for stiff meshes."""
        jac = self.jacobian() if method in ("BDF", "Radau", "LSODA") else None
        return solve_ivp(lambda t, T: self.rhs(T, inputs(t)), t_span, np.asarray(T0, dtype=float), method=method,
                         jac=jac, t_eval=t_eval, rtol=rtol, atol=atol, max_step=max_step)
