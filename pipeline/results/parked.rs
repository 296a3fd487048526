//! A part of a run's result the campaign need not hold while its other
//! runs go on: held as computed, or parked in a store (the job's scratch
//! file, `run::scratch`) once the run's own files are written, and read
//! back for the set's files. Parking is invisible in every output: the
//! part serialises, compares and prints as the value it stands for, and
//! is kept as CBOR, which gives back every f64 to the bit.

use std::borrow::Cow;
use std::fmt;
use std::sync::Arc;

use serde::de::DeserializeOwned;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// Where parked parts are kept, read back by where they were kept.
pub trait PartStore: Send + Sync + fmt::Debug {
    /// The `len` bytes kept at `at`, as they were kept.
    fn read(&self, at: u64, len: usize) -> Vec<u8>;
}

/// A value in memory, or parked in a [`PartStore`]. A held value is boxed,
/// so that a parked one leaves no more than its place in the store behind.
#[derive(Clone)]
pub struct Parked<T>(Place<T>);

#[derive(Clone)]
enum Place<T> {
    Held(Box<T>),
    Stored {
        store: Arc<dyn PartStore>,
        at: u64,
        len: usize,
    },
}

impl<T> Parked<T> {
    /// `value`, held.
    pub fn new(value: T) -> Self {
        Self(Place::Held(Box::new(value)))
    }

    /// Whether the value is in a store rather than in memory.
    pub fn is_stored(&self) -> bool {
        matches!(self.0, Place::Stored { .. })
    }
}

impl<T> From<T> for Parked<T> {
    fn from(value: T) -> Self {
        Self::new(value)
    }
}

impl<T: Clone + DeserializeOwned> Parked<T> {
    /// The value: borrowed where it is held, read back where it is parked.
    ///
    /// Panics where a parked value cannot be decoded: it was encoded by
    /// [`Parked::park`] in this process, and the store panics on its own
    /// where it cannot read.
    pub fn get(&self) -> Cow<'_, T> {
        match &self.0 {
            Place::Held(value) => Cow::Borrowed(&**value),
            Place::Stored { store, at, len } => {
                let bytes = store.read(*at, *len);
                Cow::Owned(
                    ciborium::from_reader(bytes.as_slice())
                        .expect("a parked part decodes as it was encoded"),
                )
            }
        }
    }
}

impl<T: Serialize> Parked<T> {
    /// Park a held value: `keep` writes its bytes to a store and says
    /// where, or None where it cannot (the value then stays held).
    pub fn park(&mut self, keep: impl FnOnce(&[u8]) -> Option<(Arc<dyn PartStore>, u64)>) {
        let Place::Held(value) = &self.0 else {
            return;
        };
        let mut bytes = Vec::new();
        if ciborium::into_writer(value, &mut bytes).is_err() {
            return;
        }
        if let Some((store, at)) = keep(&bytes) {
            let len = bytes.len();
            self.0 = Place::Stored { store, at, len };
        }
    }
}

impl<T: Clone + DeserializeOwned + Serialize> Serialize for Parked<T> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        self.get().serialize(s)
    }
}

impl<'de, T: Deserialize<'de>> Deserialize<'de> for Parked<T> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        T::deserialize(d).map(Self::new)
    }
}

impl<T: Clone + DeserializeOwned + fmt::Debug> fmt::Debug for Parked<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.get().fmt(f)
    }
}

impl<T: Clone + DeserializeOwned + PartialEq> PartialEq for Parked<T> {
    fn eq(&self, other: &Self) -> bool {
        *self.get() == *other.get()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    /// A store in memory.
    #[derive(Debug, Default)]
    struct Memory(Mutex<Vec<u8>>);

    impl Memory {
        /// `bytes` kept at the end; the store and where they start.
        fn keep(store: &Arc<Self>, bytes: &[u8]) -> Option<(Arc<dyn PartStore>, u64)> {
            let mut held = store.0.lock().unwrap();
            let at = held.len() as u64;
            held.extend_from_slice(bytes);
            Some((Arc::clone(store) as Arc<dyn PartStore>, at))
        }
    }

    impl PartStore for Memory {
        fn read(&self, at: u64, len: usize) -> Vec<u8> {
            let at = at as usize;
            self.0.lock().unwrap()[at..at + len].to_vec()
        }
    }

    #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
    struct Part {
        x: Vec<f64>,
        note: Option<String>,
        #[serde(default, skip_serializing_if = "Vec::is_empty")]
        empty: Vec<u8>,
    }

    /// Every f64 comes back to the bit (those CBOR writes in two or four
    /// bytes, subnormals, infinities, a NaN's payload, a negative zero),
    /// and the parked part serialises to the JSON the held one does.
    #[test]
    fn a_parked_part_reads_back_to_the_bit() {
        let nan = f64::from_bits(0x7ff8_0000_dead_beef);
        let x = vec![
            0.5,
            1.0 / 3.0,
            -0.0,
            f64::MIN_POSITIVE / 3.0,
            f64::INFINITY,
            nan,
            1e300,
            65504.0,
            0.1f32 as f64,
        ];
        let part = Part {
            x,
            note: Some("why".into()),
            empty: Vec::new(),
        };
        let store = Arc::new(Memory::default());
        store.0.lock().unwrap().extend([7u8; 5]);
        let mut parked = Parked::new(part.clone());
        parked.park(|bytes| Memory::keep(&store, bytes));
        assert!(parked.is_stored());
        let back = parked.get();
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&back.x), bits(&part.x));
        assert_eq!(back.note, part.note);
        // JSON writes the NaN and the infinity as null, so compare without.
        let finite = Part {
            x: part.x[..4].iter().chain(&part.x[6..]).copied().collect(),
            ..part.clone()
        };
        let mut finite_parked = Parked::new(finite.clone());
        finite_parked.park(|bytes| Memory::keep(&store, bytes));
        assert_eq!(
            serde_json::to_string(&finite_parked).unwrap(),
            serde_json::to_string(&finite).unwrap()
        );
        // A store that cannot keep it leaves it held.
        let mut held = Parked::new(part.clone());
        held.park(|_| None);
        assert!(!held.is_stored());
        assert!(matches!(held.get(), Cow::Borrowed(_)));
    }
}
