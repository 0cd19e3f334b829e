//! The integration tests: one binary, every test runnable on lavapipe.

#[path = "../../examples/embed/host.rs"]
mod host;
mod support;

mod adaptive;
mod attached;
mod attached_glass;
mod batch;
mod bvh_embree;
mod cli;
mod conductor_ior;
mod conformance;
mod cpu_vs_gpu;
mod embed;
mod embree_smoke;
mod furnace;
mod gradients;
mod hardening;
mod loop_budget;
mod media;
mod normal_maps;
mod optimize;
mod optimize_cli;
mod resources;
mod scene_formats;
mod strategies;
mod twins;
mod variance;
mod views;
