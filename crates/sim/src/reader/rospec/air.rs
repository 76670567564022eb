//! How the running AISpec inventories on an antenna: the RF mode (C1G2RFControl ModeIndex and
//! Tari), the Gen2 session (C1G2SingulationControl) and Impinj's search mode
//! (ImpinjInventorySearchMode), from the ROSpec's antenna configuration or else the reader's.

use llrp::params::{C1g2InventoryCommand, Custom, InventoryParameterSpec};

use crate::physics::gen2::{Air, Target};
use crate::reader::config::ReaderConfig;

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
    let in_spec = ips.into_iter().flat_map(|p| {
        p.antenna_configuration
            .iter()
            .filter(move |c| c.antenna_id == antenna || c.antenna_id == 0)
    });
    let in_config = config.antennas.get(usize::from(antenna).saturating_sub(1));
    let commands: Vec<&C1g2InventoryCommand> = in_spec
        .chain(in_config)
        .flat_map(|c| c.c1g2_inventory_command.iter())
        .collect();
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
