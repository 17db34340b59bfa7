//! Integrators: the path tracer.
