//! The simulated reader of llrp-gateway without IO: the scenario file ([`scenario`]), the
//! channel model, pure functions of scenario, simulated time and seed ([`physics`]), and the
//! reader as a sans-IO session, bytes and time in, bytes and the next deadline out
//! ([`reader`]). It knows the codec and nothing above it: no sockets, no async runtime, no
//! localizer (ARCHITECTURE.md).

pub mod physics;
pub mod reader;
pub mod scenario;
