//! The integration tests: one binary, every test runnable on lavapipe.

mod support;

mod cli;
mod cpu_vs_gpu;
mod embree_smoke;
mod furnace;
mod twins;
