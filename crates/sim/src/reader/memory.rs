//! Tag memory as the tags hold it during a simulator's run: the four Gen2 banks, their lock
//! states and whether a tag was killed, changed by access operations and shared by every
//! reader of the run (a tag is one chip, whichever reader writes it).
//!
//! A tag no operation has changed is read from the scenario ([`Model`]) directly; the first
//! operation on a tag copies it into the store ([`Chip`]), so that inventories of tags nobody
//! wrote cost no lock. The rules are GS1's (EPC UHF Gen2 Air Interface Protocol v2.0.1,
//! §6.3.2.1 memory, §6.3.2.11.3.5 Lock, Tables 6.45–6.46): an access password of 0 puts a tag
//! straight into the secured state; a locked bank is writable only there; a permalocked one
//! never; a locked password is neither readable nor writable outside it; a permalock bit once
//! set cannot be cleared; a tag whose kill password is 0 does not kill; the StoredCRC is not
//! writable.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Mutex;

use crate::physics::Model;
use crate::scenario::tagmem::TagEpc;

/// Why an access operation on a tag failed (the LLRP result of each operation names these).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fault {
    /// Words beyond the end of the bank.
    Overrun,
    /// The memory (or password) is locked against this operation in the tag's state.
    Locked,
    /// The access (or kill) password given does not match the tag's.
    Password,
    /// Kill with the tag's kill password 0: the tag does not kill.
    ZeroKillPassword,
    /// Any other error the tag backscatters (a write to the StoredCRC).
    Tag,
    /// The tag ignores the command and does not reply (a Lock in the open state), or the
    /// reply is lost (the tag faded out of the field: `access::link`).
    Ignored,
    /// The tag has too little power to program its memory (Gen2 error code 0x0B).
    Power,
}

/// The lock bits of one field (Gen2 Table 6.45): pwd-write or pwd-read/write, and permalock.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Lock {
    /// Writable (readable, for a password) only in the secured state.
    pub locked: bool,
    /// The `locked` bit can never change again.
    pub perma: bool,
}

/// What a Lock payload does to a field (LLRP C1G2LockPrivilege).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Privilege {
    /// Read_Write (0): locked, not permanently.
    ReadWrite,
    /// Perma_Lock (1): locked for ever.
    PermaLock,
    /// Perma_Unlock (2): unlocked for ever.
    PermaUnlock,
    /// Unlock (3).
    Unlock,
}

impl Privilege {
    /// The privilege of an LLRP C1G2LockPrivilege value (0–3).
    pub fn from_llrp(v: u8) -> Option<Privilege> {
        Some(match v {
            0 => Privilege::ReadWrite,
            1 => Privilege::PermaLock,
            2 => Privilege::PermaUnlock,
            3 => Privilege::Unlock,
            _ => return None,
        })
    }

    fn bits(self) -> Lock {
        let (locked, perma) = match self {
            Privilege::ReadWrite => (true, false),
            Privilege::PermaLock => (true, true),
            Privilege::PermaUnlock => (false, true),
            Privilege::Unlock => (false, false),
        };
        Lock { locked, perma }
    }
}

/// Kill password, access password, EPC, TID and user memory: LLRP's C1G2LockDataField order.
pub const LOCK_FIELDS: usize = 5;
const KILL_PWD: usize = 0;
const ACCESS_PWD: usize = 1;

/// Words of EPC memory (after StoredCRC and PC) a tag has at least: 128 bits, Impinj Monza
/// 4QT's EPC memory (Monza 4 Tag Chip Datasheet, memory map).
pub const EPC_MEMORY_WORDS: usize = 8;

/// One tag's memory once an operation has touched it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Chip {
    /// Reserved memory: kill password (words 0–1), access password (words 2–3).
    pub reserved: [u16; 4],
    /// EPC memory from word 1: the PC word, then the EPC memory (zeros past the EPC).
    pub epc: Vec<u16>,
    /// TID memory.
    pub tid: Vec<u16>,
    /// User memory.
    pub user: Vec<u16>,
    /// Lock bits per field, in [`LOCK_FIELDS`] order.
    pub locks: [Lock; LOCK_FIELDS],
    /// Killed: it never answers again.
    pub killed: bool,
}

impl Chip {
    /// Tag `tag` as the scenario gives it: TID permalocked, as manufacturers ship it.
    pub fn from_model(model: &Model, tag: usize) -> Chip {
        let epc = model.tag_epc(tag);
        let mut words = vec![epc.pc()];
        words.extend(
            epc.as_bytes()
                .chunks_exact(2)
                .map(|c| u16::from_be_bytes([c[0], c[1]])),
        );
        words.resize(1 + epc.words().max(EPC_MEMORY_WORDS), 0);
        Chip::shipped(
            model.tag_passwords(tag),
            words,
            model.tag_tid(tag),
            model.tag_user(tag),
        )
    }

    /// A tag as manufacturers ship it: the (kill, access) passwords, EPC memory from the PC
    /// word, TID and User memory, the TID permalocked.
    pub fn shipped(passwords: (u32, u32), epc: Vec<u16>, tid: Vec<u16>, user: Vec<u16>) -> Chip {
        let (kill, access) = passwords;
        let mut locks = [Lock::default(); LOCK_FIELDS];
        locks[3] = Lock {
            locked: true,
            perma: true,
        };
        Chip {
            reserved: [
                (kill >> 16) as u16,
                kill as u16,
                (access >> 16) as u16,
                access as u16,
            ],
            epc,
            tid,
            user,
            locks,
            killed: false,
        }
    }

    fn access_password(&self) -> u32 {
        u32::from(self.reserved[2]) << 16 | u32::from(self.reserved[3])
    }

    fn kill_password(&self) -> u32 {
        u32::from(self.reserved[0]) << 16 | u32::from(self.reserved[1])
    }

    /// Whether the tag is in the secured state after an access with `password` (0: none
    /// given), or the password is wrong.
    fn secured(&self, password: u32) -> Result<bool, Fault> {
        let own = self.access_password();
        if password != 0 && password != own {
            return Err(Fault::Password);
        }
        Ok(own == 0 || password == own)
    }

    /// The EPC as inventories report it: the PC word's length field's words of EPC memory.
    pub fn reported_epc(&self) -> TagEpc {
        let words = usize::from(self.epc[0] >> 11).clamp(1, self.epc.len() - 1);
        let bytes: Vec<u8> = self.epc[1..=words]
            .iter()
            .flat_map(|w| w.to_be_bytes())
            .collect();
        // 1 to 31 whole words (the length field has 5 bits and is clamped to at least 1).
        TagEpc::from_bytes(&bytes).expect("1 to 31 whole words")
    }

    /// Bank `mb` as a reader reads it (EPC memory with its StoredCRC first).
    pub fn bank(&self, mb: u8) -> Vec<u16> {
        match mb {
            0 => self.reserved.to_vec(),
            1 => {
                let epc = self.reported_epc();
                let mut w = vec![crate::reader::report::gen2_crc(self.epc[0], epc.as_bytes())];
                w.extend_from_slice(&self.epc);
                w
            }
            2 => self.tid.clone(),
            _ => self.user.clone(),
        }
    }

    /// The lock field guarding words `start..end` of bank `mb` (Reserved: one per password).
    fn fields(mb: u8, start: usize, end: usize) -> Vec<usize> {
        match mb {
            0 => [(0..2, KILL_PWD), (2..4, ACCESS_PWD)]
                .into_iter()
                .filter(|(r, _)| start < r.end && end > r.start)
                .map(|(_, f)| f)
                .collect(),
            1 => vec![2],
            2 => vec![3],
            _ => vec![4],
        }
    }

    /// Reads `count` words of bank `mb` from `pointer` (0: to the end of the bank).
    pub fn read(&self, mb: u8, pointer: u16, count: u16, password: u32) -> Result<Vec<u16>, Fault> {
        let secured = self.secured(password)?;
        let words = self.bank(mb);
        let start = usize::from(pointer);
        let end = if count == 0 {
            words.len()
        } else {
            start + usize::from(count)
        };
        if start > end || end > words.len() || (count == 0 && start >= words.len()) {
            return Err(Fault::Overrun);
        }
        // Only the passwords are read-locked.
        if mb == 0
            && Self::fields(mb, start, end)
                .into_iter()
                .any(|f| self.locks[f].locked && (self.locks[f].perma || !secured))
        {
            return Err(Fault::Locked);
        }
        Ok(words[start..end].to_vec())
    }

    /// Whether words `start..end` of bank `mb` may be written with `password`.
    fn writable(&self, mb: u8, start: usize, end: usize, password: u32) -> Result<(), Fault> {
        let secured = self.secured(password)?;
        let len = match mb {
            0 => 4,
            1 => self.epc.len() + 1,
            2 => self.tid.len(),
            _ => self.user.len(),
        };
        if end > len {
            return Err(Fault::Overrun);
        }
        if mb == 1 && start == 0 {
            // The StoredCRC is the tag's own (Gen2 §6.3.2.1.2.1).
            return Err(Fault::Tag);
        }
        let locked = Self::fields(mb, start, end)
            .into_iter()
            .any(|f| self.locks[f].locked && (self.locks[f].perma || !secured));
        if locked {
            return Err(Fault::Locked);
        }
        Ok(())
    }

    fn word_mut(&mut self, mb: u8, i: usize) -> &mut u16 {
        match mb {
            0 => &mut self.reserved[i],
            1 => &mut self.epc[i - 1],
            2 => &mut self.tid[i],
            _ => &mut self.user[i],
        }
    }

    /// Writes `data` into bank `mb` from `pointer` a word at a time, as a reader does with
    /// Gen2 Write commands: the words written before a fault stay written. Gives the words
    /// written and the fault that stopped it, if any.
    pub fn write(
        &mut self,
        mb: u8,
        pointer: u16,
        data: &[u16],
        password: u32,
    ) -> (u16, Option<Fault>) {
        let start = usize::from(pointer);
        let mut written = 0u16;
        for (k, &w) in data.iter().enumerate() {
            if let Err(f) = self.writable(mb, start + k, start + k + 1, password) {
                return (written, Some(f));
            }
            *self.word_mut(mb, start + k) = w;
            written += 1;
        }
        (written, None)
    }

    /// Writes `data` into bank `mb` from `pointer` in one BlockWrite: all of it or nothing.
    pub fn block_write(
        &mut self,
        mb: u8,
        pointer: u16,
        data: &[u16],
        password: u32,
    ) -> Result<u16, Fault> {
        let start = usize::from(pointer);
        self.writable(mb, start, start + data.len(), password)?;
        for (k, &w) in data.iter().enumerate() {
            *self.word_mut(mb, start + k) = w;
        }
        // At most u16::MAX words: the LLRP field's count.
        Ok(data.len() as u16)
    }

    /// Erases (sets to 0) `count` words of bank `mb` from `pointer`: all or nothing.
    pub fn erase(&mut self, mb: u8, pointer: u16, count: u16, password: u32) -> Result<(), Fault> {
        let start = usize::from(pointer);
        let end = start + usize::from(count);
        self.writable(mb, start, end, password)?;
        for i in start..end {
            *self.word_mut(mb, i) = 0;
        }
        Ok(())
    }

    /// Applies Lock payloads `(privilege, field)` (fields in [`LOCK_FIELDS`] order) at once,
    /// or none of them. The tag must be secured; a permalocked field's bits cannot change.
    pub fn lock(&mut self, payloads: &[(Privilege, usize)], password: u32) -> Result<(), Fault> {
        if !self.secured(password)? {
            // Lock is not a command of the open state: the tag ignores it.
            return Err(Fault::Ignored);
        }
        let mut next = self.locks;
        for &(p, f) in payloads {
            let want = p.bits();
            let now = self.locks.get(f).copied().ok_or(Fault::Tag)?;
            if now.perma && (now.locked != want.locked || !want.perma) {
                return Err(Fault::Locked);
            }
            next[f] = want;
        }
        self.locks = next;
        Ok(())
    }

    /// Kills the tag with `password`.
    pub fn kill(&mut self, password: u32) -> Result<(), Fault> {
        let own = self.kill_password();
        if own == 0 {
            return Err(Fault::ZeroKillPassword);
        }
        if password != own {
            return Err(Fault::Password);
        }
        self.killed = true;
        Ok(())
    }
}

/// The memory of every tag of a run, shared by its readers.
#[derive(Debug, Default)]
pub struct TagMemory {
    /// Whether any tag has been copied into `chips` (until then every read is the scenario's).
    touched: AtomicBool,
    /// Counts the operations that may have changed a tag (see [`TagMemory::generation`]).
    generation: AtomicU64,
    chips: Mutex<HashMap<usize, Chip>>,
}

impl TagMemory {
    /// Every tag as its scenario gives it.
    pub fn new() -> TagMemory {
        TagMemory::default()
    }

    fn chips(&self) -> std::sync::MutexGuard<'_, HashMap<usize, Chip>> {
        // A panic while holding the lock leaves whole words behind: the map stays usable.
        self.chips.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// What an inventory reports of tag `tag`: its EPC and PC word, or `None` once it is
    /// killed.
    #[inline]
    pub fn epc(&self, model: &Model, tag: usize) -> Option<(TagEpc, u16)> {
        let scenario = || {
            let epc = model.tag_epc(tag);
            (epc, epc.pc())
        };
        if !self.touched.load(Ordering::Acquire) {
            return Some(scenario());
        }
        match self.chips().get(&tag) {
            Some(c) if c.killed => None,
            Some(c) => Some((c.reported_epc(), c.epc[0])),
            None => Some(scenario()),
        }
    }

    /// Runs `f` on tag `tag`'s memory, copying it from the scenario on first use.
    pub fn with_chip<R>(&self, model: &Model, tag: usize, f: impl FnOnce(&mut Chip) -> R) -> R {
        let mut chips = self.chips();
        let chip = chips
            .entry(tag)
            .or_insert_with(|| Chip::from_model(model, tag));
        self.touched.store(true, Ordering::Release);
        self.generation.fetch_add(1, Ordering::AcqRel);
        f(chip)
    }

    /// A number that changes whenever an operation may have changed a tag's memory: what was
    /// worked out from the memory (the tags a Select matches) still holds while it stays.
    pub fn generation(&self) -> u64 {
        self.generation.load(Ordering::Acquire)
    }

    /// Whether any tag has been killed.
    pub fn any_killed(&self) -> bool {
        self.touched.load(Ordering::Acquire) && self.chips().values().any(|c| c.killed)
    }

    /// Every tag an operation has touched, by scenario index, in index order.
    pub fn snapshot(&self) -> Vec<(usize, Chip)> {
        let mut all: Vec<(usize, Chip)> =
            self.chips().iter().map(|(k, c)| (*k, c.clone())).collect();
        all.sort_by_key(|(k, _)| *k);
        all
    }

    /// Puts `chips` (by scenario index) in place of those tags' memory.
    pub fn restore(&self, chips: Vec<(usize, Chip)>) {
        let mut held = self.chips();
        for (k, c) in chips {
            held.insert(k, c);
        }
        self.touched.store(true, Ordering::Release);
        self.generation.fetch_add(1, Ordering::AcqRel);
    }

    /// `f` of tag `tag`'s memory as it is now, without copying a tag an operation touched
    /// (the memory is locked while `f` runs: `f` must not use it).
    pub fn inspect<R>(&self, model: &Model, tag: usize, f: impl FnOnce(&Chip) -> R) -> R {
        if self.touched.load(Ordering::Acquire) {
            if let Some(c) = self.chips().get(&tag) {
                return f(c);
            }
        }
        f(&Chip::from_model(model, tag))
    }

    /// A copy of tag `tag`'s memory as it is now.
    pub fn chip(&self, model: &Model, tag: usize) -> Chip {
        if self.touched.load(Ordering::Acquire) {
            if let Some(c) = self.chips().get(&tag) {
                return c.clone();
            }
        }
        Chip::from_model(model, tag)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An EPC-96 tag with the given passwords, 4 words of user memory, TID permalocked.
    fn chip(kill: u32, access: u32) -> Chip {
        let mut epc = vec![0x3000, 0x3008, 0x33B2, 0xDDD9, 0x0140, 0, 1];
        epc.resize(1 + EPC_MEMORY_WORDS, 0);
        let tid = vec![0xE280, 0x1160, 1, 2, 3, 4];
        Chip::shipped((kill, access), epc, tid, vec![0; 4])
    }

    #[test]
    fn writes_stop_at_the_end_of_the_bank_and_keep_what_they_wrote() {
        let mut c = chip(0, 0);
        assert_eq!(c.write(3, 2, &[7, 8, 9], 0), (2, Some(Fault::Overrun)));
        assert_eq!(c.user, vec![0, 0, 7, 8]);
        // A BlockWrite is all or nothing.
        assert_eq!(c.block_write(3, 3, &[1, 2], 0), Err(Fault::Overrun));
        assert_eq!(c.user, vec![0, 0, 7, 8]);
        assert_eq!(c.read(3, 4, 1, 0), Err(Fault::Overrun));
        assert_eq!(c.read(3, 2, 0, 0), Ok(vec![7, 8]));
    }

    #[test]
    fn the_pc_word_sets_the_length_of_the_reported_epc_and_the_crc_is_the_tags() {
        let mut c = chip(0, 0);
        assert_eq!(c.reported_epc().words(), 6);
        assert_eq!(
            c.write(1, 1, &[0x2000, 0x1111, 0x2222, 0x3333, 0x4444], 0),
            (5, None)
        );
        assert_eq!(
            c.reported_epc().as_bytes(),
            [0x11, 0x11, 0x22, 0x22, 0x33, 0x33, 0x44, 0x44]
        );
        assert_eq!(c.write(1, 0, &[0], 0), (0, Some(Fault::Tag)));
        // The bank as read starts with the CRC of what the PC word says the EPC is.
        let bank = c.bank(1);
        assert_eq!(bank[1], 0x2000);
        assert_eq!(
            bank[0],
            crate::reader::report::gen2_crc(
                0x2000,
                &[0x11, 0x11, 0x22, 0x22, 0x33, 0x33, 0x44, 0x44]
            )
        );
    }

    #[test]
    fn a_locked_bank_is_writable_only_with_the_access_password() {
        let mut c = chip(0, 0xABCD);
        let lock = [(Privilege::ReadWrite, 4)];
        assert_eq!(c.lock(&lock, 0), Err(Fault::Ignored));
        assert_eq!(c.lock(&lock, 0x1234), Err(Fault::Password));
        assert_eq!(c.lock(&lock, 0xABCD), Ok(()));
        assert_eq!(c.write(3, 0, &[5], 0), (0, Some(Fault::Locked)));
        assert_eq!(c.write(3, 0, &[5], 0xABCD), (1, None));
        // Reads of user memory are never locked.
        assert_eq!(c.read(3, 0, 1, 0), Ok(vec![5]));
    }

    #[test]
    fn with_access_password_zero_every_access_is_secured() {
        let mut c = chip(0, 0);
        assert_eq!(c.lock(&[(Privilege::ReadWrite, 4)], 0), Ok(()));
        assert_eq!(c.write(3, 0, &[5], 0), (1, None));
    }

    #[test]
    fn permalock_bits_cannot_be_undone_and_the_tid_ships_permalocked() {
        let mut c = chip(0, 0);
        assert_eq!(c.lock(&[(Privilege::PermaLock, 4)], 0), Ok(()));
        assert_eq!(c.lock(&[(Privilege::Unlock, 4)], 0), Err(Fault::Locked));
        assert_eq!(
            c.lock(&[(Privilege::PermaUnlock, 4)], 0),
            Err(Fault::Locked)
        );
        // Asserting what is already permanent is allowed.
        assert_eq!(c.lock(&[(Privilege::PermaLock, 4)], 0), Ok(()));
        assert_eq!(c.write(3, 0, &[1], 0), (0, Some(Fault::Locked)));
        assert_eq!(c.write(2, 0, &[1], 0), (0, Some(Fault::Locked)));
        assert_eq!(c.lock(&[(Privilege::Unlock, 3)], 0), Err(Fault::Locked));
        // A refused payload leaves the others of the same Lock undone too.
        assert_eq!(
            c.lock(&[(Privilege::ReadWrite, 2), (Privilege::Unlock, 3)], 0),
            Err(Fault::Locked)
        );
        assert_eq!(c.locks[2], Lock::default());
    }

    #[test]
    fn a_read_locked_password_is_readable_only_when_secured() {
        let mut c = chip(0x1111_2222, 0xABCD);
        assert_eq!(c.read(0, 0, 4, 0), Ok(vec![0x1111, 0x2222, 0, 0xABCD]));
        assert_eq!(c.lock(&[(Privilege::ReadWrite, 1)], 0xABCD), Ok(()));
        assert_eq!(c.read(0, 2, 2, 0), Err(Fault::Locked));
        assert_eq!(c.read(0, 0, 2, 0), Ok(vec![0x1111, 0x2222]));
        assert_eq!(c.read(0, 2, 2, 0xABCD), Ok(vec![0, 0xABCD]));
        assert_eq!(c.write(0, 2, &[0, 0], 0), (0, Some(Fault::Locked)));
    }

    #[test]
    fn kill_needs_a_nonzero_kill_password_and_the_right_one() {
        let mut c = chip(0, 0);
        assert_eq!(c.kill(0), Err(Fault::ZeroKillPassword));
        let mut c = chip(0x1234_5678, 0);
        assert_eq!(c.kill(0x1234_0000), Err(Fault::Password));
        assert!(!c.killed);
        assert_eq!(c.kill(0x1234_5678), Ok(()));
        assert!(c.killed);
    }

    #[test]
    fn erase_zeroes_the_words_or_none() {
        let mut c = chip(0, 0);
        c.user = vec![1, 2, 3, 4];
        assert_eq!(c.erase(3, 1, 2, 0), Ok(()));
        assert_eq!(c.user, vec![1, 0, 0, 4]);
        assert_eq!(c.erase(3, 3, 2, 0), Err(Fault::Overrun));
        assert_eq!(c.user, vec![1, 0, 0, 4]);
    }
}
