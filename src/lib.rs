//! llrp-gateway: a simulated LLRP reader, a transparent gateway to real readers and a tag
//! localizer. The LLRP codec lives in the `llrp` crate (`protocol/`).

pub mod decode;
pub mod net;
pub mod physics;
pub mod reader;
pub mod scenario;
pub mod sim;
