"""A backend wrapper for tests that look at what the hybrid loop asked the integrator (dynamics/backend.py)."""
from mechsim.dynamics.backend import Backend


class Recording(Backend):
    """Wraps a backend and keeps every request it integrates and every segment it returns."""

    def __init__(self, inner):
        self.inner, self.requests, self.segments = inner, [], []
        for key in ("name", "solver", "initial_step", "recoverable", "unavailable", "notes"):
            setattr(self, key, getattr(inner, key))

    def hint(self, code):
        return self.inner.hint(code)

    def integrate(self, request):
        self.requests.append(request)
        seg = self.inner.integrate(request)
        self.segments.append(seg)
        return seg
