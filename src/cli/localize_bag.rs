//! `localize` with MCAP files: the reads of an MCAP file this project wrote (its
//! `llrp_gateway_msgs/msg/TagRead` channels), and the antenna poses from a robot's own bag
//! (`--poses BAG.mcap --pose-topic TOPIC [--frames PARENT,...,ROBOT]`, each antenna at its
//! offset in the robot frame: `--antenna-offset` or the settings' `antenna_offsets`).

use std::collections::BTreeSet;
use std::path::Path;

use crate::cli::bag_poses::{antenna_samples, robot_track};
use crate::localize::offline::AntennaOffset;
use crate::localize::poses::Poses;
use crate::reads::{Read, ReaderName};
use crate::record::mcap::read::{topics_in_words, Bag, BagError};
use crate::record::mcap::ros_in;

/// The `TagRead` schema's name.
const TAG_READ: &str = "llrp_gateway_msgs/msg/TagRead";

/// The reads of every `llrp_gateway_msgs/msg/TagRead` channel of the MCAP file at `path`.
pub fn bag_reads(path: &Path) -> Result<Vec<Read>, BagError> {
    let bag = Bag::open(path)?;
    let (messages, topics) = bag.messages(|_| true)?;
    let mut reads = Vec::new();
    for m in messages.iter().filter(|m| m.schema == TAG_READ) {
        let read = ros_in::tag_read(&m.data)
            .map_err(|e| BagError::new(path, Some(&m.topic), format!("a TagRead: {e}")))?;
        reads.push(read);
    }
    if reads.is_empty() {
        return Err(BagError::new(
            path,
            None,
            format!("no {TAG_READ} messages ({})", topics_in_words(&topics)),
        ));
    }
    Ok(reads)
}

/// The antenna poses of each (reader, antenna) of `reads` along the robot's poses in the bag
/// at `path` (`topic`, and the chain `frames` for `/tf`), at `offsets`.
pub fn bag_poses(
    path: &Path,
    topic: &str,
    frames: &[String],
    offsets: &[AntennaOffset],
    reads: &[Read],
) -> Result<Poses, BagError> {
    let bag = Bag::open(path)?;
    let track = robot_track(&bag, topic, frames)?;
    let antennas: BTreeSet<(Option<ReaderName>, u16)> = reads
        .iter()
        .map(|r| (r.reader.clone(), r.antenna))
        .collect();
    let antennas: Vec<_> = antennas.into_iter().collect();
    let mut poses = Poses::new();
    for s in antenna_samples(&track, &antennas, offsets, path, topic)? {
        poses.add(s);
    }
    Ok(poses)
}

/// `--antenna-offset [ANTENNA=]X,Y,Z,YAW_DEG` (m, m, m, degrees; Z and YAW_DEG may be left
/// out): the antenna's offset in the robot frame, for every antenna without `ANTENNA=`.
pub fn parse_offset(text: &str) -> Result<AntennaOffset, String> {
    let (antenna, values) = match text.split_once('=') {
        Some((a, v)) => (
            Some(
                a.trim()
                    .parse::<u16>()
                    .map_err(|_| format!("{a:?} is not an antenna port"))?,
            ),
            v,
        ),
        None => (None, text),
    };
    let v: Vec<f64> = values
        .split(',')
        .map(|v| {
            v.trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| format!("{v:?} is not a number"))
        })
        .collect::<Result<_, _>>()?;
    if !(2..=4).contains(&v.len()) {
        return Err("give X,Y[,Z[,YAW_DEG]] (m and degrees), e.g. 0.2,-0.3,0.5,-90".into());
    }
    Ok(AntennaOffset {
        reader: None,
        antenna,
        x: v[0],
        y: v[1],
        z: v.get(2).copied().unwrap_or(0.0),
        yaw_deg: v.get(3).copied().unwrap_or(0.0),
    })
}

#[cfg(test)]
mod tests {
    use super::parse_offset;

    #[test]
    fn an_antenna_offset_parses_with_or_without_its_port() {
        let o = parse_offset("0.2,-0.3,0.5,-90").expect("parses");
        assert_eq!(
            (o.antenna, o.x, o.y, o.z, o.yaw_deg),
            (None, 0.2, -0.3, 0.5, -90.0)
        );
        let o = parse_offset("2=1,2").expect("parses");
        assert_eq!(
            (o.antenna, o.x, o.y, o.z, o.yaw_deg),
            (Some(2), 1.0, 2.0, 0.0, 0.0)
        );
        assert!(parse_offset("1").is_err());
        assert!(parse_offset("x=1,2").is_err());
        assert!(parse_offset("1,nan").is_err());
    }
}
