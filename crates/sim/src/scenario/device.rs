//! The reader devices a scenario reader can present itself as (`"device"`): their names,
//! antenna ports and GPIO ports. The reader's `device` module holds what each one is; a unit test there
//! keeps the two lists the same. A device is not a reader model (`"reader_model"`,
//! [`super::profile`]): the model sets how the radio behaves, the device what the reader says
//! it is and which LLRP tables and extensions it has.

use super::validate::{invalid, Check};
use super::ReaderSpec;

/// Every device's name, antenna ports, GPI ports and GPO ports; the first is the default.
pub const DEVICES: [(&str, usize, u16, u16); 3] = [
    ("impinj-r420", 4, 4, 4),
    ("impinj-r700", 4, 2, 3),
    ("zebra-fx9600", 8, 4, 4),
];

/// The (GPI, GPO) ports of device `name` (`None` or an unknown name: the default device's).
pub fn gpio(name: Option<&str>) -> (u16, u16) {
    let (_, _, gpis, gpos) = name
        .and_then(|n| DEVICES.iter().find(|d| d.0 == n))
        .unwrap_or(&DEVICES[0]);
    (*gpis, *gpos)
}

/// Checks a reader's `device`: a known name, with no more antennas than it has ports.
pub(super) fn validate(p: &str, r: &ReaderSpec) -> Check {
    let Some(name) = r.device.as_deref() else {
        return Ok(());
    };
    let Some(&(_, ports, _, _)) = DEVICES.iter().find(|d| d.0 == name) else {
        let known: Vec<&str> = DEVICES.iter().map(|d| d.0).collect();
        return Err(invalid(
            format!("{p}.device"),
            format!("unknown device `{name}`; known: {}", known.join(", ")),
        ));
    };
    if r.antennas.len() > ports {
        return Err(invalid(
            format!("{p}.antennas"),
            format!(
                "the {name} has {ports} antenna ports, the reader lists {} antennas",
                r.antennas.len()
            ),
        ));
    }
    Ok(())
}
