//! Inventory: turning an antenna's share of the reader's time into tag reads.
//!
//! Each attempt slot (see [`super::schedule`]) happens at one instant on the channel of that
//! instant. The tags in the field are those within r·(1 + 4σ_r) whose forward link powers the
//! chip (P_tag ≥ tag sensitivity, with multipath when the scenario has reflectors), evaluated
//! every 10 ms of absolute time; the attempt picks one of them at random, computes its channel
//! at the attempt's instant, and becomes a read only if
//! 1. D ≤ r̃ = r·|1 + n_r|, n_r ~ N(0, σ_r²) drawn for this attempt (\[G\]);
//! 2. a uniform draw falls below the edge probability of the forward-link margin (0 when the
//!    tag is not powered);
//! 3. the noisy RSSI log argument is positive and the RSSI reaches the reader's sensitivity.
//!
//! Free space uses \[G\] eq. 5 for RSSI and 4πD/λ for phase; with reflectors both come from the
//! summed image paths (\[G\] eq. 1).

use rand::Rng;

use super::geometry::distance;
use super::multipath::{self, Channel};
use super::schedule::{self, Slot};
use super::{noise, phase, rssi, AntennaPose, Model, Read};
use crate::scenario::AntennaSpec;

/// Half-interval (µs) of the central difference giving the radial velocity.
const DOPPLER_STEP_US: u64 = 10_000;

/// Number of σ_r beyond the nominal range still considered in the field.
const RANGE_SIGMAS: f64 = 4.0;

/// The field (which tags an attempt may pick) is recomputed every this many µs of absolute
/// time; the picked tag's channel is then computed at the attempt's exact instant.
const FIELD_BUCKET_US: u64 = 10_000;

impl Model {
    /// Reads made on antenna `antenna` (1-based) during simulated time `[t0_us, t1_us)`, in
    /// time order. `tx_power_dbm` is the power the client configured (`None`: the scenario's
    /// value); it sets the read range and the RSSI. The window is entirely this antenna's: it
    /// gets `reads_per_second · (t1 − t0)` attempts. Deterministic: each attempt's draws are
    /// seeded by (seed, reader, antenna, slot), so the same window always gives the same
    /// reads and a split window gives the same reads as the whole.
    pub fn inventory(
        &self,
        antenna: u16,
        t0_us: u64,
        t1_us: u64,
        tx_power_dbm: Option<f64>,
    ) -> Vec<Read> {
        self.inventory_on(antenna, t0_us, t1_us, tx_power_dbm, None)
    }

    /// As [`Model::inventory`], but on channel `channel` (1-based) for the whole window when
    /// given — e.g. the ChannelIndex a client set in a fixed-frequency region; an index outside
    /// the table is ignored (the hop schedule applies).
    pub fn inventory_on(
        &self,
        antenna: u16,
        t0_us: u64,
        t1_us: u64,
        tx_power_dbm: Option<f64>,
        channel: Option<u16>,
    ) -> Vec<Read> {
        let Some(a) = usize::from(antenna)
            .checked_sub(1)
            .and_then(|i| self.antennas.get(i))
        else {
            return Vec::new();
        };
        let tx = tx_power_dbm
            .filter(|p| p.is_finite())
            .unwrap_or(a.spec.tx_power_dbm);
        let pinned = channel.filter(|c| (1..=self.table.len()).contains(&usize::from(*c)));
        let key = [self.seed, self.reader as u64, u64::from(antenna)];
        let mut field: (u64, Vec<usize>) = (u64::MAX, Vec::new());
        let mut reads = Vec::new();
        for slot in schedule::slots(key, self.reads_per_second, t0_us, t1_us) {
            let bucket = slot.time_us / FIELD_BUCKET_US;
            if field.0 != bucket {
                let start = bucket * FIELD_BUCKET_US;
                let ch = pinned.unwrap_or_else(|| self.channel_at(start));
                field = (bucket, self.field(antenna, tx, start, ch));
            }
            let ch = pinned.unwrap_or_else(|| self.channel_at(slot.time_us));
            if let Some(read) = self.attempt(antenna, tx, ch, slot, &field.1) {
                reads.push(read);
            }
        }
        reads
    }

    /// The tags in the field of `antenna` at `t_us` on `channel`: within r·(1 + 4σ_r) and
    /// powered.
    fn field(&self, antenna: u16, tx_power_dbm: f64, t_us: u64, channel: u16) -> Vec<usize> {
        let spec = &self.antennas[usize::from(antenna) - 1].spec;
        let lambda = self.wavelength_m(channel);
        let pose = self.antenna_pose(antenna, t_us);
        let reach = spec.range_m * (1.0 + RANGE_SIGMAS * spec.range_sigma);
        (0..self.tags.len())
            .filter(|&tag| {
                let position = self.tag_position(tag, t_us);
                distance(pose.position, position) <= reach
                    && self
                        .margin_db(spec, &pose, position, lambda, tx_power_dbm)
                        .1
                        >= 0.0
            })
            .collect()
    }

    /// The channel to a tag at `position` and its forward-link margin over the tag's
    /// sensitivity (dB).
    fn margin_db(
        &self,
        spec: &AntennaSpec,
        pose: &AntennaPose,
        position: [f64; 3],
        lambda: f64,
        tx_power_dbm: f64,
    ) -> (Channel, f64) {
        let ch = multipath::channel(
            pose,
            spec.gain_dbi,
            spec.beamwidth_deg,
            position,
            &self.reflectors,
            lambda,
        );
        let p_tag = rssi::tag_power_dbm(
            tx_power_dbm,
            spec.cable_loss_db,
            ch.gain_linear,
            rssi::db_to_linear(rssi::TAG_GAIN_DBI),
            lambda,
            ch.distance_m,
            ch.multipath_factor,
        );
        (ch, p_tag - spec.tag_sensitivity_dbm)
    }

    /// One read attempt on `antenna` on `channel_index` at the slot's instant, on one tag of
    /// `field`.
    fn attempt(
        &self,
        antenna: u16,
        tx_power_dbm: f64,
        channel_index: u16,
        slot: Slot,
        field: &[usize],
    ) -> Option<Read> {
        let Slot {
            time_us, mut rng, ..
        } = slot;
        if field.is_empty() {
            return None;
        }
        let tag = field[rng.gen_range(0..field.len())];
        let spec = &self.antennas[usize::from(antenna) - 1].spec;
        let frequency_khz = *self.table.get(usize::from(channel_index) - 1)?;
        let lambda = self.wavelength_m(channel_index);
        let pose = self.antenna_pose(antenna, time_us);
        let position = self.tag_position(tag, time_us);
        let (ch, margin_db) = self.margin_db(spec, &pose, position, lambda, tx_power_dbm);

        let perturbed_range =
            spec.range_m * (1.0 + noise::gaussian(&mut rng, spec.range_sigma)).abs();
        if ch.distance_m > perturbed_range {
            return None;
        }
        if rng.gen::<f64>() >= schedule::read_probability(margin_db) {
            return None;
        }
        let n_rssi = noise::gaussian(&mut rng, spec.rssi_noise);
        let rssi_dbm = if self.reflectors.is_empty() {
            rssi::simplified_dbm(
                tx_power_dbm,
                spec.cable_loss_db,
                ch.gain_linear,
                lambda,
                ch.distance_m,
                n_rssi,
            )
        } else {
            rssi::full_model(
                tx_power_dbm,
                spec.cable_loss_db,
                ch.gain_linear,
                rssi::db_to_linear(rssi::TAG_GAIN_DBI),
                lambda,
                ch.distance_m,
                ch.multipath_factor,
                n_rssi,
            )
        }?;
        if rssi_dbm < rssi::READER_SENSITIVITY_DBM {
            return None;
        }
        let mut n_phi = noise::gaussian(&mut rng, spec.phase_noise_rad);
        if let Some(dist) = &spec.extra_phase_noise {
            n_phi += noise::extra(&mut rng, dist);
        }
        let phi0 = self.phase_offset(antenna, tag, channel_index);
        let phase_rad = phase::reported_phase(ch.delay_rad, phi0, spec.phase_sign, n_phi);
        Some(Read {
            tag,
            antenna,
            time_us,
            channel_index,
            frequency_khz,
            rssi_dbm,
            phase_rad,
            doppler_hz: self.doppler_hz(antenna, tag, time_us, lambda),
        })
    }

    /// Doppler shift (Hz) of `tag` seen by `antenna` at `t_us`, from the radial velocity
    /// (central difference of the true distance over ±10 ms; one-sided at t = 0).
    pub fn doppler_hz(&self, antenna: u16, tag: usize, t_us: u64, wavelength_m: f64) -> f64 {
        let range = |t| {
            distance(
                self.antenna_pose(antenna, t).position,
                self.tag_position(tag, t),
            )
        };
        let before = t_us.saturating_sub(DOPPLER_STEP_US);
        let after = t_us.saturating_add(DOPPLER_STEP_US);
        let dt_s = (after - before) as f64 * 1e-6;
        let v_r = (range(after) - range(before)) / dt_s;
        let f = phase::doppler_hz(v_r, wavelength_m);
        if f.is_finite() {
            f
        } else {
            0.0
        }
    }
}
