//! End-to-end tests of the service, in one test binary: real servers on loopback ports, driven
//! over HTTP and WebSocket, and the browser viewer driven in headless Chromium.

mod api;
mod bad_inputs;
mod budgets;
mod costs;
mod hardening;
mod routing;
mod scene_store;
mod schemathesis;
mod streaming;
mod video;
mod viewer;
