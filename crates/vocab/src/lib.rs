//! The vocabulary every layer of llrp-gateway shares, below the localizer, the simulator and
//! the application: a tag's EPC with its one case rule ([`epc`]), a reader's name with its
//! one rule ([`reader_name`]), tag reads in SI units decoded from LLRP ([`reads`]), the one
//! antenna pose in SI units and its timed sample ([`pose`]), the feed that carries both from
//! any source to any consumer ([`feed`]), the sans-IO server session every LLRP server here
//! implements ([`session`]), CSV as every file here has it ([`table`]) and the wall clock
//! ([`utc`]). It knows the codec and nothing above
//! it (ARCHITECTURE.md).

pub mod epc;
pub mod feed;
pub mod pose;
pub mod reader_name;
pub mod reads;
pub mod session;
pub mod table;
pub mod utc;
