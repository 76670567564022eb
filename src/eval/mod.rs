//! Evaluation tools that drive the simulator and the localizer from above: `bench localize`
//! ([`mod@bench`]: a scenario simulated faster than real time, localized by every estimator,
//! scored against the truth), its live part ([`live`]: read-to-HTTP latency), the Monte-Carlo
//! variants of S3 ([`montecarlo`]), the plot ([`plot`]), and `bench readrate` ([`readrate`]:
//! the read rate against the tags in the field). Their command lines and tables are
//! `cli::bench`. The localizer itself ([`crate::localize`]) sees only reads and poses; these
//! tools hold the truth beside them.

pub mod bench;
pub mod live;
pub mod montecarlo;
pub mod plot;
pub mod readrate;
