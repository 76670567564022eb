//! An MCAP file's LLRP frame channels (`llrp_gateway_msgs/msg/LlrpFrame`, as `export --mcap`
//! writes them) as a recording ([`crate::record::Recording`]), for `replay FILE.mcap`: each
//! message a frame (or, `whole_frame` false, the bytes that were not one) of its connection
//! and direction, at its `header.stamp` (when the gateway received it).

use std::path::Path;

use super::read::{topics_in_words, Bag, BagError};
use super::ros_in;
use crate::record::{Entry, Header, Recording, Stamp};

/// The `LlrpFrame` schema's name.
const LLRP_FRAME: &str = "llrp_gateway_msgs/msg/LlrpFrame";

/// The recording of the LLRP frames in the MCAP file at `path` (its `upstream` the frames'
/// reader, its start the first frame's time).
pub fn recording(path: &Path) -> Result<Recording, BagError> {
    let bag = Bag::open(path)?;
    let (messages, topics) = bag.messages(|_| true)?;
    let mut frames = Vec::new();
    for m in messages.iter().filter(|m| m.schema == LLRP_FRAME) {
        let f = ros_in::llrp_frame(&m.data)
            .map_err(|e| BagError::new(path, Some(&m.topic), format!("an LlrpFrame: {e}")))?;
        frames.push(f);
    }
    let Some(first) = frames.first() else {
        return Err(BagError::new(
            path,
            None,
            format!(
                "no {LLRP_FRAME} messages to replay ({})",
                topics_in_words(&topics)
            ),
        ));
    };
    let start_utc_us = frames
        .iter()
        .map(|f| f.received_ns.div_euclid(1000))
        .min()
        .unwrap_or(0);
    let start_utc_us = u64::try_from(start_utc_us)
        .map_err(|_| BagError::new(path, None, "a frame stamped before 1970"))?;
    let mut header = Header::new(first.reader.clone(), start_utc_us);
    header.gateway = format!(
        "llrp-gateway {} (from {})",
        env!("CARGO_PKG_VERSION"),
        path.display()
    );
    let entries = frames
        .into_iter()
        .map(|f| {
            // Every stamp is at or after the start, the smallest of them.
            let utc_us = u64::try_from(f.received_ns.div_euclid(1000)).unwrap_or(start_utc_us);
            let at = Stamp {
                t_us: utc_us - start_utc_us,
                utc_us,
            };
            let data = bytes::Bytes::from(f.data);
            if f.whole_frame {
                Entry::Frame {
                    at,
                    conn: f.conn,
                    dir: f.dir,
                    frame: data,
                    undecodable: None,
                }
            } else {
                Entry::Bytes {
                    at,
                    conn: f.conn,
                    dir: f.dir,
                    bytes: data,
                }
            }
        })
        .collect();
    Ok(Recording {
        header,
        entries,
        warnings: Vec::new(),
    })
}
