//! The recording's sensor put on a simulated V_P: what the position sensor would have read of
//! a model's positions, with the noise floor and lattice of the recording, so slips a model
//! makes are counted like those the valve made (`stickslip`).

/// The recording's sensor, for simulations: seeded Gaussian noise of the noise floor, then the
/// sensor lattice, and no reading where the recording has none (so a simulation's slips are
/// counted on the same rows as the measured ones).
pub(super) struct Sensor {
    noise: Vec<f64>,
    lattice: f64,
}

impl Sensor {
    /// The sensor of the measured V_P `vp` (NaN where missing).
    pub(super) fn new(vp: &[f64], sigma: f64, lattice: f64) -> Self {
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0x51_1b5);
        let noise = vp
            .iter()
            .map(|v| {
                let e: f64 = StandardNormal.sample(&mut rng);
                if v.is_finite() {
                    sigma * e
                } else {
                    f64::NAN
                }
            })
            .collect();
        Sensor { noise, lattice }
    }

    /// What the sensor would have read of the positions `y`.
    pub(super) fn read(&self, y: &[f64]) -> Vec<f64> {
        y.iter()
            .zip(&self.noise)
            .map(|(v, e)| {
                let r = v + e;
                if self.lattice > 0.0 {
                    (r / self.lattice).round() * self.lattice
                } else {
                    r
                }
            })
            .collect()
    }
}
