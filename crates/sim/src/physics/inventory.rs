//! Inventory: turning an antenna's share of the reader's time into tag reads.
//!
//! The reader runs Gen2 inventory rounds ([`super::rounds`]); each reply a round hears is
//! worked out here at its instant, on the channel of that instant. The tags in the field are
//! those within r·(1 + 4σ_r) whose forward link powers the chip (P_tag ≥ the tag's own
//! sensitivity, with multipath when the scenario has reflectors), evaluated at the start of
//! each 25 ms epoch; a reply becomes a read only if
//! 1. D ≤ r̃ = r·|1 + n_r|, n_r ~ N(0, σ_r²) drawn for this reply (\[G\]);
//! 2. a uniform draw falls below the edge probability of the forward-link margin (0 when the
//!    tag is not powered);
//! 3. the RSSI (docs/measurement.md) reaches the reader's sensitivity.
//!
//! Free space and multipath share one gain convention; the phase comes from the direct path
//! or the summed image paths (\[G\] eq. 1).

use rand::Rng;

use super::field::Bucket;
use super::flags::Flags;
use super::gen2::Air;
use super::geometry::{distance, Vec3};
use super::multipath::{self, Aim, Channel};
use super::schedule;
use super::seed::Stream;
use super::{hardware, noise, phase, rssi, Model, Read, Want};
use crate::scenario::{AntennaSpec, RssiModel};

/// Half-interval (µs) of the central difference giving the radial velocity.
const DOPPLER_STEP_US: u64 = 10_000;

/// Number of σ_r beyond the nominal range still considered in the field.
pub(super) const RANGE_SIGMAS: f64 = 4.0;

/// The field (which tags take part in an epoch's rounds) is recomputed every this many µs of
/// absolute time; a reply's channel is then computed at its exact instant. One antenna
/// dwell of the reader's rotation (`reader::rospec::ANTENNA_DWELL_US`), so a slice that starts
/// on the grid sees one field, as the tags energised at the start of an inventory round take
/// part in it.
pub(super) const FIELD_BUCKET_US: u64 = 25_000;

impl Model {
    /// Reads made on antenna `antenna` (1-based) during simulated time `[t0_us, t1_us)`, in
    /// time order, under the reader's default [`Air`]. `tx_power_dbm` is the power the client
    /// configured (`None`: the scenario's value); it sets the read range and the RSSI. The
    /// window is entirely this antenna's. Deterministic: every draw is seeded by (seed,
    /// reader, antenna, epoch, reply), so the same window always gives the same reads and a
    /// split window gives the same reads as the whole.
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
        let air = Air::default();
        self.inventory_with(
            antenna,
            t0_us,
            t1_us,
            tx_power_dbm,
            channel,
            Want::ALL,
            &air,
        )
    }

    /// As [`Model::inventory_on`], under `air` (RF mode, session, target), working out only
    /// the optional values `want` asks for (the same reads, with the others 0). Every tag
    /// takes part in every round (session 0, dual target); see [`Model::inventory_flagged`].
    #[allow(clippy::too_many_arguments)]
    pub fn inventory_with(
        &self,
        antenna: u16,
        t0_us: u64,
        t1_us: u64,
        tx_power_dbm: Option<f64>,
        channel: Option<u16>,
        want: Want,
        air: &Air,
    ) -> Vec<Read> {
        let none = None;
        self.inventory_in(
            antenna,
            t0_us,
            t1_us,
            tx_power_dbm,
            channel,
            want,
            air,
            none,
        )
        .0
    }

    /// As [`Model::inventory_with`] for a single-target inventory in session 1–3
    /// ([`Air::suppresses`]), with rounds from `t0_us` on: only the tags whose flag in `flags` is A
    /// take part, each at most once; the caller sends a tag to B when it reports its read
    /// ([`Flags::read`]). Also says whether no tag was in A when the first round began.
    #[allow(clippy::too_many_arguments)]
    pub fn inventory_flagged(
        &self,
        antenna: u16,
        t0_us: u64,
        t1_us: u64,
        tx_power_dbm: Option<f64>,
        channel: Option<u16>,
        want: Want,
        air: &Air,
        flags: &mut Flags,
    ) -> (Vec<Read>, bool) {
        let flags = air.suppresses().then_some(flags);
        self.inventory_in(
            antenna,
            t0_us,
            t1_us,
            tx_power_dbm,
            channel,
            want,
            air,
            flags,
        )
    }

    #[allow(clippy::too_many_arguments)]
    fn inventory_in(
        &self,
        antenna: u16,
        t0_us: u64,
        t1_us: u64,
        tx_power_dbm: Option<f64>,
        channel: Option<u16>,
        want: Want,
        air: &Air,
        flags: Option<&mut Flags>,
    ) -> (Vec<Read>, bool) {
        let Some(a) = usize::from(antenna)
            .checked_sub(1)
            .and_then(|i| self.antennas.get(i))
        else {
            return (Vec::new(), flags.is_some());
        };
        let tx = tx_power_dbm
            .filter(|p| p.is_finite())
            .unwrap_or(a.spec.tx_power_dbm);
        let pinned = channel.filter(|c| (1..=self.table.len()).contains(&usize::from(*c)));
        // The antenna's field state from its last window: its kept decisions and buffers.
        let index = usize::from(antenna) - 1;
        let mut bucket = self.field_cache.take_bucket(index);
        bucket.memo.fit(self.tags.len(), tx);
        let reads = self.rounds(
            antenna,
            t0_us,
            t1_us,
            tx,
            pinned,
            want,
            air,
            &mut bucket,
            flags,
        );
        self.field_cache.put_bucket(index, bucket);
        reads
    }

    /// The channel from `antenna` aimed as `aim` to tag `tag` at `position` (its delay only
    /// if `delay`, see [`multipath::channel_of`]; its `gain_linear` times the tag's
    /// orientation factor, [`super::tag::TagRadio::gain_factor`], since both links use only
    /// the product of the two gains) and its forward-link margin over the tag's own
    /// sensitivity (dB).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn margin_with(
        &self,
        antenna: u16,
        tag: usize,
        aim: &Aim,
        position: Vec3,
        lambda: f64,
        tx_power_dbm: f64,
        delay: bool,
    ) -> (Channel, f64) {
        let a = &self.antennas[usize::from(antenna) - 1];
        let mut ch = multipath::channel_of(aim, &a.pattern, position, &self.planes, lambda, delay);
        let radio = &self.tags[tag].radio;
        ch.gain_linear *= radio.gain_factor(aim.position, position);
        let p_tag = rssi::tag_power_dbm(
            tx_power_dbm,
            a.spec.cable_loss_db,
            ch.gain_linear,
            self.tag_gain_linear,
            lambda,
            ch.distance_m,
            ch.multipath_factor,
        );
        (
            ch,
            p_tag - a.spec.tag_sensitivity_dbm - radio.sensitivity_db,
        )
    }

    /// The read `tag` makes answering `antenna` on `channel_index` at `time_us`, if the
    /// reader decodes it, with every draw from `rng`.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn reply_at(
        &self,
        antenna: u16,
        tx_power_dbm: f64,
        channel_index: u16,
        tag: usize,
        time_us: u64,
        rng: &mut Stream,
        bucket: &mut Bucket,
        want: Want,
    ) -> Option<Read> {
        let spec = &self.antennas[usize::from(antenna) - 1].spec;
        let frequency_khz = *self.table.get(usize::from(channel_index) - 1)?;
        let lambda = self.wavelength_m(channel_index);
        let (ch, margin_db) = self.link(
            bucket,
            antenna,
            tag,
            time_us,
            channel_index,
            tx_power_dbm,
            want.phase,
        );

        let perturbed_range = spec.range_m * (1.0 + noise::gaussian(rng, spec.range_sigma)).abs();
        if ch.distance_m > perturbed_range {
            return None;
        }
        if rng.gen::<f64>() >= schedule::read_probability(margin_db) {
            return None;
        }
        let hw = &self.antennas[usize::from(antenna) - 1].hardware;
        // What hardware adds to the level: compression at strong signal and the fixed
        // per-channel response (0 at the defaults).
        let backscatter_db = self.tags[tag].radio.backscatter_db
            - hardware::compression_db(
                margin_db,
                spec.compression_knee_db,
                spec.backscatter_compression,
            )
            + hw.rssi_db(tag, channel_index);
        // The noise-free level sets the phase and Doppler noise in both models.
        let (clean_dbm, rssi_dbm) =
            self.reply_levels(spec, &ch, tx_power_dbm, lambda, backscatter_db, rng)?;
        if rssi_dbm < rssi::READER_SENSITIVITY_DBM {
            return None;
        }
        // The phase and Doppler draws come last from the reply's generator, always in the
        // same order when either is asked for: leaving both undrawn changes nothing else, and
        // asking for one gives it the same value as asking for both.
        let (mut phase_rad, mut doppler_hz) = (0.0, 0.0);
        if want.phase || want.doppler {
            let (n_phi, n_doppler) = phase_doppler_noise(spec, clean_dbm, rng);
            if want.phase {
                let phi0 = self.phase_offset(antenna, tag, channel_index)
                    + self.pattern_phase(antenna, tag, time_us);
                phase_rad = phase::reported_phase(ch.delay_rad, phi0, spec.phase_sign, n_phi);
                if spec.phase_resolution_bits < 12 {
                    phase_rad = hardware::quantise_phase(phase_rad, spec.phase_resolution_bits);
                }
            }
            if want.doppler {
                doppler_hz = self.doppler_hz(antenna, tag, time_us, lambda) + n_doppler;
            }
        }
        Some(Read {
            tag,
            antenna,
            time_us,
            channel_index,
            frequency_khz,
            rssi_dbm,
            phase_rad,
            doppler_hz,
            margin_db,
        })
    }

    /// The noise-free and the reported level (dBm) of a reply over channel `ch` at
    /// `tx_power_dbm` and `lambda` (m), the hardware adding `backscatter_db`, with the RSSI
    /// model's draws from `rng`; `None` when the link model gives no level.
    #[inline]
    fn reply_levels(
        &self,
        spec: &AntennaSpec,
        ch: &Channel,
        tx_power_dbm: f64,
        lambda: f64,
        backscatter_db: f64,
        rng: &mut Stream,
    ) -> Option<(f64, f64)> {
        let rx = |noise| {
            rssi::full_model(
                tx_power_dbm,
                spec.cable_loss_db,
                ch.gain_linear,
                self.tag_gain_linear,
                lambda,
                ch.distance_m,
                ch.multipath_factor,
                noise,
            )
            .map(|dbm| dbm + backscatter_db)
        };
        match spec.rssi_model {
            RssiModel::Reader => {
                let clean = rx(0.0)?;
                let scale = if spec.rssi_sigma_grows {
                    noise::weak_signal_scale_with(
                        clean,
                        spec.phase_noise_ref_dbm,
                        spec.noise_exponent,
                    )
                } else {
                    1.0
                };
                let n_db = noise::gaussian(rng, spec.rssi_sigma_db * scale)
                    + hardware::rssi_outlier(rng, spec.rssi_outlier_rate);
                Some((
                    clean,
                    rssi::reader_dbm(clean, n_db, spec.rssi_resolution_db),
                ))
            }
            RssiModel::GazeboEq5 => {
                let n_rssi = noise::gaussian(rng, spec.eq5_noise());
                let noisy = rx(n_rssi)?;
                Some((rx(0.0).unwrap_or(noisy), noisy))
            }
        }
    }

    /// The smooth angle-dependent phase error (rad) of `tag` read by `antenna` at `t_us`:
    /// the antenna's pattern in its own frame plus the tag's against the direction it is read
    /// from, both grown by the angle off the antenna's boresight, plus the tag's curvature
    /// a·θ² (0 when there is none of them).
    fn pattern_phase(&self, antenna: u16, tag: usize, t_us: u64) -> f64 {
        let a = &self.antennas[usize::from(antenna) - 1];
        let radio = &self.tags[tag].radio;
        if a.hardware.phase_field.is_none()
            && radio.phase_field.is_none()
            && radio.phase_curvature_rad == 0.0
        {
            return 0.0;
        }
        let pose = self.antenna_pose(antenna, t_us);
        let at = self.tag_position(tag, t_us);
        let b = super::geometry::boresight(pose.yaw_rad, pose.pitch_rad);
        let seen = hardware::in_antenna_frame(hardware::direction(pose.position, at), b);
        let mut sum = 0.0;
        if let Some(f) = &a.hardware.phase_field {
            sum += f.at(seen);
        }
        if let Some(f) = &radio.phase_field {
            sum += f.at(hardware::direction(at, pose.position));
        }
        // Both grow off the antenna's boresight (seen[2] is the cosine of that angle).
        let off_axis = seen[2].clamp(-1.0, 1.0).acos();
        sum * hardware::pattern_growth(off_axis, a.hardware.pattern_growth_rad)
            + hardware::curvature_phase(radio.phase_curvature_rad, off_axis)
    }

    /// Doppler shift (Hz) of `tag` seen by `antenna` at `t_us`, from the radial velocity
    /// (central difference of the true distance over ±10 ms; one-sided at t = 0).
    pub fn doppler_hz(&self, antenna: u16, tag: usize, t_us: u64, wavelength_m: f64) -> f64 {
        let range = |t| distance(self.antenna_position(antenna, t), self.tag_position(tag, t));
        let before = t_us.saturating_sub(DOPPLER_STEP_US);
        let after = t_us.saturating_add(DOPPLER_STEP_US);
        let dt_s = (after - before) as f64 * 1e-6;
        let still = self
            .antennas
            .get(usize::from(antenna).wrapping_sub(1))
            .is_some_and(|a| before >= a.rest_us);
        // Once nothing moves the two ranges are the same number.
        let v_r = if still {
            0.0
        } else {
            (range(after) - range(before)) / dt_s
        };
        let f = phase::doppler_hz(v_r, wavelength_m);
        if f.is_finite() {
            f
        } else {
            0.0
        }
    }
}

/// The phase noise (rad) and Doppler noise (Hz) of a reply whose noise-free level is
/// `clean_dbm`, drawn from `rng` in this order.
#[inline]
fn phase_doppler_noise(spec: &AntennaSpec, clean_dbm: f64, rng: &mut Stream) -> (f64, f64) {
    let scale =
        noise::weak_signal_scale_with(clean_dbm, spec.phase_noise_ref_dbm, spec.noise_exponent);
    let sigma = spec.phase_noise_rad * scale;
    let mut n_phi = hardware::heavy(rng, sigma, spec.phase_noise_dof);
    if let Some(dist) = &spec.extra_phase_noise {
        n_phi += noise::extra(rng, dist);
    }
    if spec.phase_pi_ambiguity && rng.gen::<bool>() {
        n_phi += std::f64::consts::PI;
    }
    n_phi += hardware::phase_outlier(rng, spec.phase_outlier_rate, sigma);
    let n_doppler = noise::gaussian(rng, spec.doppler_sigma_hz * scale);
    (n_phi, n_doppler)
}
