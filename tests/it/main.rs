//! The integration-test binary: every integration test is a module here, so they link once.

mod embree_smoke;
mod support;
