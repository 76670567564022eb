//! The command line's commands that drive a subsystem from above and are not part of it
//! (issue 42 gathers the command line here, one command at a time): `localize` ([`localize`]).

pub mod localize;
