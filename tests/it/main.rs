//! The integration tests: one binary, every test runnable on lavapipe.

mod support;

mod bvh_embree;
mod embree_smoke;
mod loop_budget;
mod twins;
