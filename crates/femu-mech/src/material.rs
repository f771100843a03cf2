//! Hyperelastic materials for plane strain (F33 = 1) and their registry.
//!
//! **The registry.** A law is one type implementing [`MaterialLaw`] in one file of this module,
//! registered by one line in the list below ([`LAWS`]); deck reading and writing
//! ([`material_from_def`], [`material_def`]), study-file keys ([`material_from_keys`]), the
//! model's parameters and their sensitivities ([`crate::sensitivity`]) and the element kernels
//! ([`Material::evaluate_element`]) all work from what the law declares. The steps are in
//! `docs/adding-a-material.md`.
//!
//! Every material is written through the invariants `I1 = tr(F^T F)` (3D, so it includes
//! `F33^2 = 1`) and `J = det F`, which gives the first Piola–Kirchhoff stress and its consistent
//! tangent in closed form:
//!
//! ```text
//! P = 2 W_I F + W_J cof(F)
//! A = dP/dF = 4 W_II F⊗F + 2 W_IJ (F⊗cof + cof⊗F) + W_JJ cof⊗cof + 2 W_I 𝕀 + W_J dcof/dF
//! ```
//!
//! where `cof(F) = J F^-T` is linear in F in two dimensions. The isochoric and volumetric parts
//! are kept apart so that the hybrid element (CPE4H) can replace `U(J)` by `U(θ)` with the
//! element's mean dilatation θ.

pub mod hyperelastic;
pub mod law;
mod registry;

pub use hyperelastic::*;
pub use law::{
    AbaqusField, Bound, LawSpec, Material, MaterialError, MaterialLaw, ParameterSpec, Unit,
};
pub use registry::{
    law, law_for_keyword, material_def, material_from_def, material_from_keys, parameter_key,
    set_from_keys, LawEntry,
};

/// Declares each law's module (`pub mod`, the file of the same name here), re-exports its type
/// and lists it in [`LAWS`].
macro_rules! register_laws {
    ($($module:ident :: $law:ident),+ $(,)?) => {
        $(pub mod $module; pub use $module::$law;)+
        /// The registered laws, in registration order.
        pub static LAWS: &[LawEntry] =
            &[$(LawEntry::of::<$law>(&<$law as MaterialLaw>::SPEC)),+];
    };
}

// The registry: one line per law.
register_laws! {
    neo_hookean::NeoHookean,
    mooney_rivlin::MooneyRivlin,
    yeoh::Yeoh,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mat() -> NeoHookean {
        NeoHookean::new(1.75e-3, 18.0).unwrap()
    }

    /// `inv_cbrt` against `1 / cbrt` on deformations (0.5 to 1.5) and far beyond (1e-40 to
    /// 1e40, both branches), seeded.
    #[test]
    fn inverse_cube_root_is_within_one_and_a_half_ulp() {
        let mut x = 0x9e37_79b9_7f4a_7c15u64;
        let mut worst = 0.0f64;
        for k in 0..400_000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let u = (x >> 11) as f64 / (1u64 << 53) as f64;
            let j = if k % 2 == 0 {
                0.5 + u
            } else {
                10f64.powf(-40.0 + 80.0 * u)
            };
            let exact = 1.0 / j.cbrt();
            worst = worst.max(((inv_cbrt(j) - exact) / exact).abs() / f64::EPSILON);
        }
        assert!(worst <= 1.5, "{worst} ulp");
        assert_eq!(inv_cbrt(1.0), 1.0);
        assert_eq!(inv_cbrt(8.0), 0.5);
    }

    #[test]
    fn stress_free_reference() {
        let r = mat().response(&[1.0, 0.0, 0.0, 1.0], true).unwrap();
        assert!(r.energy.abs() < 1e-15);
        assert!(r.pk1.iter().all(|v| v.abs() < 1e-15));
        assert!(r.tau33.abs() < 1e-15);
    }

    #[test]
    fn small_strain_moduli() {
        // Uniaxial-strain-free simple shear γ: σxy ≈ μ γ with μ = 2 C10.
        let m = mat();
        let g = 1e-6;
        let r = m.response(&[1.0, g, 0.0, 1.0], false).unwrap();
        let s = cauchy_from_pk1(&[1.0, g, 0.0, 1.0], &r.pk1, r.tau33);
        assert!((s[3] / g - m.shear_modulus()).abs() < 1e-6 * m.shear_modulus());
        // Equibiaxial in-plane + plane strain: mean stress ≈ K (2 e) with volumetric strain 2 e.
        let e = 1e-7;
        let f = [1.0 + e, 0.0, 0.0, 1.0 + e];
        let r = m.response(&f, false).unwrap();
        let s = cauchy_from_pk1(&f, &r.pk1, r.tau33);
        let p = (s[0] + s[1] + s[2]) / 3.0;
        assert!((p / (2.0 * e) - m.bulk_modulus()).abs() < 1e-5 * m.bulk_modulus());
    }

    #[test]
    fn log_strain_of_rotated_stretch() {
        let (s, c) = 0.3f64.sin_cos();
        // F = R diag(2, 0.5): V = R diag R^T, LE = R diag(ln 2, ln 0.5) R^T.
        let f = [c * 2.0, -s * 0.5, s * 2.0, c * 0.5];
        let le = log_strain(&f);
        let (a, b) = (2f64.ln(), 0.5f64.ln());
        let exp = [
            a * c * c + b * s * s,
            a * s * s + b * c * c,
            0.0,
            (a - b) * s * c,
        ];
        for k in 0..4 {
            assert!((le[k] - exp[k]).abs() < 1e-12, "{k}: {le:?} vs {exp:?}");
        }
    }
}
