//! Whether each reader is reached and who inventories it: written by whatever serves or
//! proxies the reader, read by whoever shows it.

use std::collections::BTreeMap;
use std::sync::{RwLock, RwLockReadGuard, RwLockWriteGuard};

use crate::reader_name::ReaderName;

/// Who runs a reader's inventory.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Inventory {
    /// No inventory runs.
    #[default]
    Idle,
    /// The connected LLRP client runs one.
    Client,
    /// A simulated reader runs its own while no client is connected.
    Own,
}

impl Inventory {
    /// The API's word for it: `idle`, `client` or `self`.
    pub fn as_str(self) -> &'static str {
        match self {
            Inventory::Idle => "idle",
            Inventory::Client => "client",
            Inventory::Own => "self",
        }
    }
}

/// One reader's link.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Link {
    /// Whether an LLRP client is connected (a simulated reader), or its upstream connection is
    /// up (a proxied reader).
    pub connected: bool,
    /// The connected peer, if any.
    pub peer: Option<String>,
    /// Who runs its inventory.
    pub inventory: Inventory,
}

/// Every reader's link, by name.
#[derive(Debug, Default)]
pub struct Links(RwLock<BTreeMap<ReaderName, Link>>);

fn read<T>(lock: &RwLock<T>) -> RwLockReadGuard<'_, T> {
    // A writer that panicked leaves the links as they were: still worth showing.
    lock.read().unwrap_or_else(|e| e.into_inner())
}

fn write<T>(lock: &RwLock<T>) -> RwLockWriteGuard<'_, T> {
    lock.write().unwrap_or_else(|e| e.into_inner())
}

impl Links {
    /// Changes reader `name`'s link (created disconnected and idle if new).
    pub fn update(&self, name: &ReaderName, f: impl FnOnce(&mut Link)) {
        let mut links = write(&self.0);
        match links.get_mut(name.as_str()) {
            Some(link) => f(link),
            None => f(links.entry(name.clone()).or_default()),
        }
    }

    /// Reader `name`'s link, if it was ever written.
    pub fn get(&self, name: &str) -> Option<Link> {
        read(&self.0).get(name).cloned()
    }

    /// Every reader's link, by name.
    pub fn all(&self) -> BTreeMap<ReaderName, Link> {
        read(&self.0).clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_link_is_created_disconnected_and_idle_and_keeps_what_was_written() {
        let links = Links::default();
        let r1 = ReaderName::parse("r1").expect("a name");
        assert_eq!(links.get("r1"), None);
        links.update(&r1, |l| {
            assert_eq!(*l, Link::default());
            l.connected = true;
            l.inventory = Inventory::Client;
        });
        links.update(&r1, |l| l.peer = Some("127.0.0.1:5".into()));
        let l = links.get("r1").expect("written above");
        assert!(l.connected);
        assert_eq!(l.peer.as_deref(), Some("127.0.0.1:5"));
        assert_eq!(l.inventory.as_str(), "client");
        assert_eq!(links.all().len(), 1);
    }
}
