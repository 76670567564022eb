//! [`ReadStream`]: a running inventory on one connection, its reports turned into typed
//! [`Read`]s, stamped with the wall clock ([`crate::utc::now_us`]).

use crate::reads::ReaderName;
use std::time::Duration;

use llrp::message::{MessageBody, MessageDef};
use llrp::Message;

use super::{Client, ClientError, InventorySpec};
use crate::reads::{Read, ReadDecoder};

use crate::utc::now_us as utc_now_us;

/// A running inventory on one connection: its reports as typed [`Read`]s, its keepalives
/// answered, and its channel frequencies from the hop table the reader itself advertises.
pub struct ReadStream {
    client: Client,
    decoder: ReadDecoder,
    rospec_id: u32,
    /// RO_ACCESS_REPORTs that did not decode (skipped).
    bad_reports: u64,
    /// Tag reads that came before this inventory's ROSpec started (dropped).
    early_reads: u64,
}

impl ReadStream {
    /// Sets up `spec` on a connected `client` (each request within `timeout`):
    /// capabilities (the hop table, and [`InventorySpec::check`]), SET_READER_CONFIG (the
    /// keepalive), IMPINJ_ENABLE_EXTENSIONS when asked, DELETE_ROSPEC 0 (whatever an earlier
    /// client left; a reader without any may say so), ADD_ROSPEC, ENABLE_ROSPEC and
    /// START_ROSPEC. Reads are labelled with `reader`. Only this inventory's reads are
    /// taken: reports that came during the setup, and reads of another ROSpec (one an earlier
    /// client left running: ROSpecs persist across connections on Impinj readers) are dropped
    /// and counted ([`Self::foreign_reads`]).
    pub async fn start(
        mut client: Client,
        spec: &InventorySpec,
        reader: Option<ReaderName>,
        timeout: Duration,
    ) -> Result<ReadStream, ClientError> {
        client.answer_keepalives(true);
        let caps = client.capabilities(timeout).await?;
        spec.check(&caps)?;
        let antenna_count = caps
            .general_device_capabilities
            .as_ref()
            .map_or(1, |g| g.max_number_of_antenna_supported);
        let mut decoder = ReadDecoder::new(reader).with_only_rospec(spec.rospec_id);
        decoder.observe(&Message::new(0, caps));
        client.check(spec.reader_config(), timeout).await?;
        if spec.impinj {
            client.enable_impinj_extensions(timeout).await?;
        }
        match client.delete_rospec(0, timeout).await {
            // No ROSpec to delete is not an error here (some readers answer with one).
            Ok(()) | Err(ClientError::Status { .. }) => {}
            Err(e) => return Err(e),
        }
        client
            .add_rospec(spec.rospec(antenna_count), timeout)
            .await?;
        client.enable_rospec(spec.rospec_id, timeout).await?;
        client.start_rospec(spec.rospec_id, timeout).await?;
        // Whatever was reported before our ROSpec started is not ours.
        let early_reads = client.discard_pending_reports() as u64;
        if early_reads > 0 {
            tracing::info!(
                "{early_reads} tag reads reported before this inventory's ROSpec started \
                 (an earlier client's ROSpec) were dropped"
            );
        }
        Ok(ReadStream {
            client,
            decoder,
            rospec_id: spec.rospec_id,
            bad_reports: 0,
            early_reads,
        })
    }

    /// Waits at most `timeout` for the next frame and appends its reads to `out` (none for
    /// frames other than RO_ACCESS_REPORT). `Err(Timeout)` if nothing came; `Err(Closed)`
    /// once the reader closed the connection, or announced it with a ConnectionCloseEvent.
    pub async fn next(
        &mut self,
        timeout: Duration,
        out: &mut Vec<Read>,
    ) -> Result<(), ClientError> {
        let frame = self.client.recv_frame(timeout).await?;
        let Some(h) = llrp::FrameHeader::peek(&frame) else {
            return Ok(());
        };
        if h.msg_type == llrp::message::ReaderEventNotification::TYPE {
            if let Ok(m) = Message::decode(&frame) {
                if m.body.is_connection_close() {
                    return Err(ClientError::Closed);
                }
            }
            return Ok(());
        }
        if self.decoder.frame(&frame, utc_now_us(), out).is_err() {
            self.bad_reports += 1;
        }
        Ok(())
    }

    /// The hop table the reads' frequencies come from (the reader's), if it advertised one.
    pub fn hop_table(&self) -> Option<&llrp::units::HopTable> {
        self.decoder.hop_table()
    }

    /// KEEPALIVEs answered on this connection.
    pub fn keepalives_answered(&self) -> u64 {
        self.client.keepalives_answered()
    }

    /// RO_ACCESS_REPORTs skipped because they did not decode.
    pub fn bad_reports(&self) -> u64 {
        self.bad_reports
    }

    /// Tag reads dropped as not this inventory's: reported before its ROSpec started, or
    /// carrying another ROSpec's ID.
    pub fn foreign_reads(&self) -> u64 {
        self.early_reads + self.decoder.foreign_reads()
    }

    /// Ends the inventory cleanly: STOP_ROSPEC and DELETE_ROSPEC (their failures ignored:
    /// the reader may have ended the spec itself), then CLOSE_CONNECTION and the reader's
    /// close, all within `timeout`. The reads the reader sends on the way (the report "at the
    /// end of the ROSpec" of reads not yet reported) are appended to `out`.
    pub async fn finish(
        mut self,
        timeout: Duration,
        out: &mut Vec<Read>,
    ) -> Result<(), ClientError> {
        let deadline = tokio::time::Instant::now() + timeout;
        let left = || deadline.saturating_duration_since(tokio::time::Instant::now());
        for stop in [true, false] {
            let r = if stop {
                self.client.stop_rospec(self.rospec_id, left()).await
            } else {
                // Answered after everything the reader sent on stopping.
                self.client.delete_rospec(self.rospec_id, left()).await
            };
            match r {
                Ok(()) | Err(ClientError::Status { .. }) => {}
                Err(e) => return Err(e),
            }
        }
        for m in self.client.drain_pending() {
            if matches!(m.body, MessageBody::RoAccessReport(_))
                && self
                    .decoder
                    .frame(&m.to_bytes(), utc_now_us(), out)
                    .is_err()
            {
                self.bad_reports += 1;
            }
        }
        self.client.close_connection(left()).await
    }
}
