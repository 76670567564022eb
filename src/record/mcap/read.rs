//! MCAP in: the messages of chosen topics of an MCAP file (this project's, or a ROS 2 bag
//! rosbag2 or another tool wrote), for `localize` and `replay`. A rosbag2 bag directory
//! (`metadata.yaml` beside its `.mcap` files) is read as its `.mcap` files in name order.
//! Errors name the file, the topic and the reason.

use std::path::{Path, PathBuf};

/// Why an MCAP file's messages could not be had.
#[derive(Debug, thiserror::Error)]
#[error("{}{}: {reason}", path.display(), in_topic(topic))]
pub struct BagError {
    /// The file.
    pub path: PathBuf,
    /// The topic, when the reason is about one.
    pub topic: Option<String>,
    /// Why.
    pub reason: String,
}

/// `: topic TOPIC`, or nothing.
fn in_topic(topic: &Option<String>) -> String {
    topic
        .as_ref()
        .map(|t| format!(": topic {t}"))
        .unwrap_or_default()
}

impl BagError {
    /// An error of `path` (and `topic`) for `reason`.
    pub fn new(path: &Path, topic: Option<&str>, reason: impl Into<String>) -> BagError {
        BagError {
            path: path.to_owned(),
            topic: topic.map(str::to_owned),
            reason: reason.into(),
        }
    }
}

/// One message of a topic.
#[derive(Clone, Debug)]
pub struct BagMessage {
    /// Its topic.
    pub topic: String,
    /// Its channel's schema name (`pkg/msg/Type`; empty without a schema).
    pub schema: String,
    /// Its log time (ns).
    pub log_time: u64,
    /// Its serialized data.
    pub data: Vec<u8>,
}

/// Every topic of a file with its schema name, in the order first seen.
pub type Topics = Vec<(String, String)>;

/// An MCAP file (or rosbag2 directory of them) read whole.
#[derive(Debug)]
pub struct Bag {
    /// The path given.
    pub path: PathBuf,
    /// Each `.mcap` file and its bytes.
    files: Vec<(PathBuf, Vec<u8>)>,
}

/// Whether `path` is an MCAP file (its magic) or a rosbag2 directory.
pub fn is_mcap(path: &Path) -> bool {
    if path.is_dir() {
        return path.join("metadata.yaml").is_file();
    }
    let mut magic = [0u8; 8];
    std::fs::File::open(path)
        .and_then(|mut f| std::io::Read::read_exact(&mut f, &mut magic))
        .is_ok()
        && magic == ::mcap::MAGIC
}

impl Bag {
    /// Reads the file (or the `.mcap` files of a rosbag2 directory) at `path`.
    pub fn open(path: &Path) -> Result<Bag, BagError> {
        let err = |reason: String| BagError::new(path, None, reason);
        let names = if path.is_dir() {
            let mut names: Vec<PathBuf> = std::fs::read_dir(path)
                .map_err(|e| err(e.to_string()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|x| x == "mcap"))
                .collect();
            names.sort();
            if names.is_empty() {
                return Err(err("a directory with no .mcap file".into()));
            }
            names
        } else {
            vec![path.to_owned()]
        };
        let mut files = Vec::new();
        for name in names {
            let bytes = std::fs::read(&name).map_err(|e| err(e.to_string()))?;
            if !bytes.starts_with(::mcap::MAGIC) {
                return Err(BagError::new(
                    &name,
                    None,
                    "not an MCAP file (no MCAP magic)",
                ));
            }
            files.push((name, bytes));
        }
        Ok(Bag {
            path: path.to_owned(),
            files,
        })
    }

    /// Every message whose topic `keep` takes, in file order, and every topic of the file with
    /// its schema name (to name in an error).
    pub fn messages(
        &self,
        keep: impl Fn(&str) -> bool,
    ) -> Result<(Vec<BagMessage>, Topics), BagError> {
        let mut out = Vec::new();
        let mut topics: Vec<(String, String)> = Vec::new();
        for (name, bytes) in &self.files {
            let stream = ::mcap::MessageStream::new(bytes)
                .map_err(|e| BagError::new(name, None, format!("not a readable MCAP file: {e}")))?;
            for m in stream {
                let m = m.map_err(|e| BagError::new(name, None, format!("bad MCAP: {e}")))?;
                let schema = m
                    .channel
                    .schema
                    .as_ref()
                    .map(|s| s.name.clone())
                    .unwrap_or_default();
                let topic = &m.channel.topic;
                if !topics.iter().any(|(t, _)| t == topic) {
                    topics.push((topic.clone(), schema.clone()));
                }
                if keep(topic) {
                    out.push(BagMessage {
                        topic: topic.clone(),
                        schema,
                        log_time: m.log_time,
                        data: m.data.into_owned(),
                    });
                }
            }
        }
        Ok((out, topics))
    }
}

/// The topics of a file in words, for an error: `/a (pkg/msg/A), /b (pkg/msg/B)`.
pub fn topics_in_words(topics: &[(String, String)]) -> String {
    if topics.is_empty() {
        return "it has no messages".into();
    }
    let list: Vec<String> = topics.iter().map(|(t, s)| format!("{t} ({s})")).collect();
    format!("its topics: {}", list.join(", "))
}
