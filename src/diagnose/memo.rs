//! A memo of model runs shared by the diagnosis' searches (fit, calibration, both unit models).

use std::collections::HashMap;
use std::sync::Mutex;

/// Values of a deterministic objective by the exact bits of its arguments (a point and a
/// horizon), shared by parallel searches: a search asks again for points it has seen (a
/// simplex's start, a zoom's centre), and a model run is deterministic. Its size is the number
/// of distinct points run, the same whichever search got to a point first.
pub struct Memo<V>(Mutex<HashMap<Vec<u64>, V>>);

impl<V> Default for Memo<V> {
    fn default() -> Self {
        Memo(Mutex::new(HashMap::new()))
    }
}

impl<V: Clone> Memo<V> {
    fn key(point: &[f64], until: f64) -> Vec<u64> {
        point.iter().chain([&until]).map(|v| v.to_bits()).collect()
    }

    pub fn get(&self, point: &[f64], until: f64) -> Option<V> {
        self.0.lock().expect("no search panics holding it").get(&Self::key(point, until)).cloned()
    }

    pub fn insert(&self, point: &[f64], until: f64, value: V) {
        self.0.lock().expect("no search panics holding it").insert(Self::key(point, until), value);
    }

    /// The value at a point, run only the first time.
    pub fn get_or(&self, point: &[f64], until: f64, run: impl FnOnce() -> V) -> V {
        if let Some(value) = self.get(point, until) {
            return value;
        }
        let value = run();
        self.insert(point, until, value.clone());
        value
    }

    /// The distinct points run.
    pub fn runs(&self) -> usize {
        self.0.lock().expect("no search panics holding it").len()
    }
}
