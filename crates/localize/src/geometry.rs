//! What an estimator is told beside the reads: the per-reader settings (from the scenario in
//! simulation, from a settings file for a real reader).

use llrp_gateway_vocab::epc::Epc;
use std::collections::BTreeMap;

/// The estimators' settings: defaults for every reader, and each reader's own where it has
/// them.
#[derive(Clone, Debug, PartialEq)]
pub struct Geometry {
    /// Height assumed for the tags by the 2D estimators (m).
    pub tag_height_m: f64,
    /// Phase sign s of φ = s·4πd/λ + φ0: +1, or −1 for a reader that reports it negated.
    pub phase_sign: f64,
    /// The side the antennas face (a horizontal direction; only its sign against the path
    /// matters): a straight path cannot tell a tag from its mirror image.
    pub facing: [f64; 2],
    /// Farthest a tag is searched for from the path (m).
    pub reach_m: f64,
    /// Reference tags at known positions, for fingerprinting and relock's calibration: (EPC
    /// upper-case hex, position in m). A reference tag is itself located from the others.
    pub references: Vec<(Epc, [f64; 3])>,
    /// Per reader name, its own phase sign and facing (the defaults above for the others).
    pub readers: BTreeMap<String, ReaderGeometry>,
    /// The antenna poses' own error, when it is known (a localization stack's, as the
    /// scenario or the settings file states it): added to every estimate's covariance
    /// ([`crate::uncertainty`]) and, where asked, taken out of the poses ([`crate::refine`]).
    pub pose_error: Option<crate::refine::PoseErrorModel>,
    /// Corrections of the antenna positions the phases were filed with, per reader and time
    /// (the live localizer's pose refinement); `None`: the positions as filed.
    pub pose_corrections: Option<std::sync::Arc<crate::refine::PoseCorrections>>,
    /// σ across tags of each tag's own phase curvature a·θ² (rad per rad²; 0: none), which a
    /// fix cannot tell from a nearer or farther tag: added to every estimate's covariance
    /// ([`crate::uncertainty::curvature_share`]).
    pub tag_curvature_sigma_rad: f64,
}

/// One reader's own settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReaderGeometry {
    /// Its phase sign: +1, or −1.
    pub phase_sign: f64,
    /// The side its antennas face.
    pub facing: [f64; 2],
}

impl Geometry {
    /// Reader `reader`'s phase sign.
    pub fn sign_of(&self, reader: &str) -> f64 {
        self.readers
            .get(reader)
            .map_or(self.phase_sign, |r| r.phase_sign)
    }

    /// The side reader `reader`'s antennas face.
    pub fn facing_of(&self, reader: &str) -> [f64; 2] {
        self.readers.get(reader).map_or(self.facing, |r| r.facing)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_reader_of_its_own_overrides_the_defaults_and_only_it() {
        // The live localizer's defaults: sign +1, facing +y.
        let mut g = crate::live::Settings::default().geometry;
        g.readers.insert(
            "left".into(),
            ReaderGeometry {
                phase_sign: -1.0,
                facing: [0.0, -1.0],
            },
        );
        assert_eq!(
            (g.sign_of("left"), g.facing_of("left")),
            (-1.0, [0.0, -1.0])
        );
        assert_eq!(
            (g.sign_of("right"), g.facing_of("right")),
            (1.0, [0.0, 1.0])
        );
    }
}
