//! The simulated readers' GPIO handed to the HTTP API: the API names no simulator, so `sim`
//! joins them here. The panels are known only once the readers are built, after the API is
//! served; until then the API sees no reader.

use std::sync::{Arc, OnceLock};

use prometheus_client::metrics::counter::Counter;

use crate::http::gpio::{GpiChange, GpiJson, GpioControl, GpioError, GpoJson, Level, ReaderGpio};
use crate::reader::gpio::{Command, GpioPanel};
use crate::reads::ReaderName;

/// The readers' GPIO panels, by name, once the readers run.
#[derive(Debug, Default)]
pub struct SimGpio {
    panels: OnceLock<Vec<(ReaderName, Arc<GpioPanel>)>>,
    /// GPI changes handed to the readers through the API (`/metrics`' `gpi_changes`).
    changes: Counter,
}

impl SimGpio {
    /// The readers' panels, in scenario order (the first call only; later ones are ignored).
    pub fn attach(&self, names: &[ReaderName], panels: &[Arc<GpioPanel>]) {
        let joined = names.iter().cloned().zip(panels.iter().cloned()).collect();
        let _ = self.panels.set(joined);
    }

    /// The counter of GPI changes handed to the readers, for the metrics registry.
    pub fn changes(&self) -> Counter {
        self.changes.clone()
    }
}

impl GpioControl for SimGpio {
    fn readers(&self) -> Vec<ReaderGpio> {
        let Some(panels) = self.panels.get() else {
            return Vec::new();
        };
        panels
            .iter()
            .map(|(name, panel)| {
                let s = panel.snapshot();
                ReaderGpio {
                    reader: name.to_string(),
                    gpis: (s.gpis.iter())
                        .map(|g| GpiJson {
                            port: g.port,
                            state: Level::of(g.high),
                            enabled: g.enabled,
                        })
                        .collect(),
                    gpos: (s.gpos.iter().enumerate())
                        .map(|(i, &high)| GpoJson {
                            port: i as u16 + 1,
                            state: Level::of(high),
                        })
                        .collect(),
                }
            })
            .collect()
    }

    fn change(&self, reader: &str, port: u16, change: GpiChange) -> Result<(), GpioError> {
        let panel = (self.panels.get().into_iter().flatten())
            .find(|(name, _)| name.as_str() == reader)
            .map(|(_, p)| p)
            .ok_or_else(|| GpioError::NoReader(reader.to_string()))?;
        let command = match change.pulse_ms {
            None => Command::Set {
                port,
                high: change.high,
            },
            Some(ms) => Command::Pulse {
                port,
                high: change.high,
                width_us: ms.saturating_mul(1000),
            },
        };
        panel
            .send(command)
            .map_err(|e| GpioError::Refused(e.to_string()))?;
        self.changes.inc();
        Ok(())
    }
}
