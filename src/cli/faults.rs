//! The simulated readers' faults handed to the HTTP API: the API names no simulator, so `sim`
//! joins them here (as `cli::gpio` does the GPIO). The panels are known only once the readers
//! are built, after the API is served; until then the API sees no reader.

use std::sync::{Arc, OnceLock};

use crate::http::faults::{FaultControl, FaultError, FaultRequest};
use crate::reader::faults::{Fault, FaultPanel};
use crate::reads::ReaderName;
use crate::scenario::faults::{DEFAULT_BOOT_MS, DEFAULT_FOR_MS};

/// The readers' fault panels, by name, once the readers run.
#[derive(Debug, Default)]
pub struct SimFaults {
    panels: OnceLock<Vec<(ReaderName, Arc<FaultPanel>)>>,
}

impl SimFaults {
    /// The readers' panels, in scenario order (the first call only; later ones are ignored).
    pub fn attach(&self, names: &[ReaderName], panels: &[Arc<FaultPanel>]) {
        let joined = names.iter().cloned().zip(panels.iter().cloned()).collect();
        let _ = self.panels.set(joined);
    }
}

/// The simulator's fault for the API's request (the defaults filled in).
fn fault_of(request: FaultRequest) -> Fault {
    match request {
        FaultRequest::AntennaDisconnect { antenna } => Fault::AntennaDisconnect { antenna },
        FaultRequest::AntennaReconnect { antenna } => Fault::AntennaReconnect { antenna },
        FaultRequest::DropConnection => Fault::DropConnection,
        FaultRequest::Reboot {
            keep_state,
            boot_ms,
        } => Fault::Reboot {
            keep_state,
            boot_ms: boot_ms.unwrap_or(DEFAULT_BOOT_MS),
        },
        FaultRequest::DelayResponses { ms, for_ms } => Fault::DelayResponses {
            ms,
            for_ms: for_ms.unwrap_or(DEFAULT_FOR_MS),
        },
        FaultRequest::LoseKeepalives { count } => Fault::LoseKeepalives { count },
        FaultRequest::FillReportBuffer { for_ms } => Fault::FillReportBuffer {
            for_ms: for_ms.unwrap_or(DEFAULT_FOR_MS),
        },
        FaultRequest::ReaderException { message } => Fault::ReaderException { message },
    }
}

impl FaultControl for SimFaults {
    fn inject(&self, reader: &str, fault: FaultRequest) -> Result<(), FaultError> {
        let panel = (self.panels.get().into_iter().flatten())
            .find(|(name, _)| name.as_str() == reader)
            .map(|(_, p)| p)
            .ok_or_else(|| FaultError::NoReader(reader.to_string()))?;
        panel
            .send(fault_of(fault))
            .map_err(|e| FaultError::Refused(e.to_string()))
    }
}
