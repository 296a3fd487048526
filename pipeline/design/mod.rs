//! Tomorrow night's runs designed from the rig servoid identified: what a
//! planned night would determine of the rig ([`precision`]) before the lab
//! runs it, the spectrum that determines it best ([`spectrum`]), and the
//! commands that carry it within the rig's limits ([`night`]). Pure: rig,
//! plans and noise in, commands and predictions out.

pub mod night;
pub mod precision;
pub mod spectrum;
