//! How the running AISpec inventories on an antenna: the RF mode (C1G2RFControl ModeIndex and
//! Tari), the Gen2 session (C1G2SingulationControl), Impinj's search mode
//! (ImpinjInventorySearchMode) and the Select filters (C1G2Filter, [`crate::reader::select`]),
//! from the ROSpec's antenna configuration or else the reader's.

use llrp::params::{C1g2InventoryCommand, Custom, InventoryParameterSpec};

use crate::physics::gen2::{Air, Target};
use crate::reader::config::ReaderConfig;
use crate::reader::select::Query;

/// ImpinjInventorySearchMode values (Impinj's LLRP extension definition).
mod search_mode {
    /// The reader picks the mode for the session.
    pub const READER_SELECTED: u16 = 0;
    /// Single target: A to B only.
    pub const SINGLE_TARGET: u16 = 1;
    /// Dual target: A to B, then B to A.
    pub const DUAL_TARGET: u16 = 2;
    /// Single target with suppression (TagFocus).
    pub const SINGLE_TARGET_WITH_SUPPRESSION: u16 = 3;
}

/// The inventory commands that apply to `antenna`: the InventoryParameterSpec's antenna
/// configurations for it (or for all) first, then the reader's configuration of it.
fn commands<'a>(
    ips: Option<&'a InventoryParameterSpec>,
    config: &'a ReaderConfig,
    antenna: u16,
) -> Vec<&'a C1g2InventoryCommand> {
    let in_spec = ips.into_iter().flat_map(|p| {
        p.antenna_configuration
            .iter()
            .filter(move |c| c.antenna_id == antenna || c.antenna_id == 0)
    });
    let in_config = config.antennas.get(usize::from(antenna).saturating_sub(1));
    in_spec
        .chain(in_config)
        .flat_map(|c| c.c1g2_inventory_command.iter())
        .collect()
}

/// The Select filters and Query of `antenna` inventoried under `air`: those of the first
/// inventory command that has filters or is state-aware (the ROSpec's before the reader
/// configuration's), with the first state-aware singulation action; `None` when none has.
pub(super) fn select_query<'a>(
    ips: Option<&'a InventoryParameterSpec>,
    config: &'a ReaderConfig,
    antenna: u16,
    air: &Air,
) -> Option<Query<'a>> {
    let commands = commands(ips, config, antenna);
    let cmd = commands
        .iter()
        .copied()
        .find(|c| !c.c1g2_filter.is_empty() || c.tag_inventory_state_aware);
    let singulation = commands.iter().find_map(|c| {
        c.c1g2_singulation_control
            .as_ref()
            .and_then(|s| s.state_aware_singulation_action.as_ref())
    });
    Query::of(cmd, singulation, air)
}

/// The [`Air`] of `antenna` under InventoryParameterSpec `ips` and the reader configuration.
///
/// Reader Selected (and no search mode at all) gives dual target: a session-2 inventory
/// without a search mode keeps rereading a static tag on a real R420 (docs/measurement.md),
/// and Impinj tells users who want each tag once to ask for Single Target themselves.
pub(super) fn air_for(
    ips: Option<&InventoryParameterSpec>,
    config: &ReaderConfig,
    antenna: u16,
) -> Air {
    let commands = commands(ips, config, antenna);
    let mut air = Air::default();
    if let Some(rf) = commands.iter().find_map(|c| c.c1g2_rf_control.as_ref()) {
        if let Some(mut mode) = config.device.mode(u32::from(rf.mode_index)).map(|m| m.link) {
            // A Tari the client chose (ns; 0 = the mode's own).
            if rf.tari > 0 {
                mode.tari_us = f64::from(rf.tari) / 1e3;
            }
            air.mode = mode;
        }
    }
    if let Some(s) = commands
        .iter()
        .find_map(|c| c.c1g2_singulation_control.as_ref())
    {
        air.session = s.session.min(3);
    }
    let search = commands
        .iter()
        .flat_map(|c| c.custom.iter())
        .find_map(|p| match p {
            Custom::ImpinjInventorySearchMode(m) => Some(m.inventory_search_mode),
            _ => None,
        });
    air.target = match search {
        Some(search_mode::SINGLE_TARGET) | Some(search_mode::SINGLE_TARGET_WITH_SUPPRESSION) => {
            Target::Single
        }
        Some(search_mode::DUAL_TARGET) | Some(search_mode::READER_SELECTED) | None => Target::Dual,
        // Other (newer) modes: dual target's steady stream.
        Some(_) => Target::Dual,
    };
    air
}
