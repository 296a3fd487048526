//! Tomorrow night's runs designed from the rig servoid identified: what a
//! planned night would determine of the rig ([`precision`]) before the lab
//! runs it, and the spectrum that determines it best ([`spectrum`]). Pure:
//! rig, plans and noise in, predictions out.

pub mod precision;
pub mod spectrum;
