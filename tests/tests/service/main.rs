//! End-to-end tests of the service, in one test binary: real servers on loopback ports, driven
//! over HTTP and WebSocket.

mod api;
mod streaming;
