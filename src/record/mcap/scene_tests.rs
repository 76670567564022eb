//! The 95 % ellipsoid of a covariance, against a covariance made from known axes.

use super::*;

/// `v` rotated by `q` (x, y, z, w).
fn rotate(q: [f64; 4], v: [f64; 3]) -> [f64; 3] {
    let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[3], q[0], q[1], q[2]));
    (q * Vector3::from(v)).into()
}

#[test]
fn an_ellipsoid_s_axes_are_the_scaled_square_roots_of_the_eigenvalues_along_the_eigenvectors() {
    // Σ = R diag(σ²) Rᵀ, R a rotation of 0.4 rad about (1, 2, 3).
    let sigmas = [0.3, 0.1, 0.02];
    let r = Rotation3::from_axis_angle(
        &nalgebra::Unit::new_normalize(Vector3::new(1.0, 2.0, 3.0)),
        0.4,
    );
    let d = Matrix3::from_diagonal(&Vector3::from(sigmas.map(|s| s * s)));
    let m = r.matrix() * d * r.matrix().transpose();
    let cov: [f64; 9] = std::array::from_fn(|i| m[(i / 3, i % 3)]);
    let el = ellipsoid(&cov).expect("a finite covariance");

    // Each of the ellipsoid's axes is one of R's columns (up to sign) with its σ × 2.796.
    let k = CHI2_95_3DOF.sqrt();
    assert!((k - 2.7955).abs() < 1e-4);
    let mut matched = [false; 3];
    for (i, a) in el.semi_axes.iter().enumerate() {
        let mut unit = [0.0; 3];
        unit[i] = 1.0;
        let axis = Vector3::from(rotate(el.orientation, unit));
        let j = (0..3)
            .find(|&j| (a - k * sigmas[j]).abs() < 1e-9)
            .unwrap_or_else(|| panic!("semi-axis {a} is no σ × {k}"));
        let column = r.matrix().column(j).into_owned();
        assert!(
            (axis.dot(&column).abs() - 1.0).abs() < 1e-9,
            "axis {i}: {axis:?} vs {column:?}"
        );
        matched[j] = true;
    }
    assert_eq!(matched, [true; 3]);

    // A point at the end of each semi-axis lies on the 95 % surface: d² = χ².
    let inverse = m.try_inverse().expect("positive definite");
    for (i, a) in el.semi_axes.iter().enumerate() {
        let mut v = [0.0; 3];
        v[i] = *a;
        let p = Vector3::from(rotate(el.orientation, v));
        let d2 = (p.transpose() * inverse * p)[(0, 0)];
        assert!((d2 - CHI2_95_3DOF).abs() < 1e-6, "axis {i}: d² {d2}");
    }
}

#[test]
fn a_flat_covariance_gives_a_flat_ellipsoid_and_a_nan_one_none() {
    // A 2D estimator's: the z row and column 0.
    let el = ellipsoid(&[0.04, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0, 0.0]).expect("finite");
    let mut axes = el.semi_axes;
    axes.sort_by(f64::total_cmp);
    let k = CHI2_95_3DOF.sqrt();
    for (got, want) in axes.iter().zip([0.0, 0.1 * k, 0.2 * k]) {
        assert!((got - want).abs() < 1e-12, "{axes:?}");
    }
    assert_eq!(ellipsoid(&[f64::NAN; 9]), None);
}

#[test]
fn a_reflector_patch_is_centred_where_the_world_s_centre_projects_onto_its_plane() {
    // The wall y = 8 (normal −y, not unit length) and a world centred at (6, 4, 1.5).
    let c = on_plane([6.0, 4.0, 1.5], [0.0, 8.0, 0.0], [0.0, -2.0, 0.0]);
    assert_eq!(c, [6.0, 8.0, 1.5]);
    // Its local +z is the plane's normal.
    let z = rotate(z_onto([0.0, -2.0, 0.0]), [0.0, 0.0, 1.0]);
    for (g, w) in z.iter().zip([0.0, -1.0, 0.0]) {
        assert!((g - w).abs() < 1e-12, "{z:?}");
    }
}

#[test]
fn an_antenna_s_lobe_opens_along_its_boresight() {
    let pose = AntennaPose {
        position: [1.0, 2.0, 0.5],
        yaw_rad: 0.7,
        pitch_rad: -0.2,
    };
    // The cone's axis (its local +z, from the apex at min z) is the boresight.
    let axis = rotate(z_onto_x(orientation(&pose)), [0.0, 0.0, 1.0]);
    let bore = super::super::geo::boresight(&pose);
    for (g, w) in axis.iter().zip(bore) {
        assert!((g - w).abs() < 1e-12, "{axis:?} vs {bore:?}");
    }
}
