//! Physical units as newtypes, so metres, seconds and speeds cannot be mixed up.
//!
//! All values are `f64` SI units. Arithmetic is only defined where the result has a meaning
//! (metres / seconds = metres per second, and so on).

use std::ops::{Add, Div, Mul, Sub};

macro_rules! unit {
    ($(#[$m:meta])* $name:ident, $sym:literal) => {
        $(#[$m])*
        #[derive(Debug, Clone, Copy, PartialEq, PartialOrd, Default, serde::Serialize, serde::Deserialize)]
        #[serde(transparent)]
        pub struct $name(pub f64);

        impl $name {
            /// The raw SI value.
            #[inline]
            pub const fn get(self) -> f64 {
                self.0
            }
            /// True when the value is neither NaN nor infinite.
            #[inline]
            pub fn is_finite(self) -> bool {
                self.0.is_finite()
            }
            /// Absolute value.
            #[inline]
            pub fn abs(self) -> Self {
                Self(self.0.abs())
            }
        }
        impl Add for $name {
            type Output = Self;
            #[inline]
            fn add(self, o: Self) -> Self {
                Self(self.0 + o.0)
            }
        }
        impl Sub for $name {
            type Output = Self;
            #[inline]
            fn sub(self, o: Self) -> Self {
                Self(self.0 - o.0)
            }
        }
        impl Mul<f64> for $name {
            type Output = Self;
            #[inline]
            fn mul(self, k: f64) -> Self {
                Self(self.0 * k)
            }
        }
        impl Div<f64> for $name {
            type Output = Self;
            #[inline]
            fn div(self, k: f64) -> Self {
                Self(self.0 / k)
            }
        }
        impl std::fmt::Display for $name {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                if let Some(p) = f.precision() {
                    write!(f, "{:.*} {}", p, self.0, $sym)
                } else {
                    write!(f, "{} {}", self.0, $sym)
                }
            }
        }
    };
}

unit!(
    /// A length in metres.
    Metres,
    "m"
);
unit!(
    /// A duration or timestamp in seconds.
    Seconds,
    "s"
);
unit!(
    /// A speed in metres per second.
    MetresPerSecond,
    "m/s"
);

impl Div<Seconds> for Metres {
    type Output = MetresPerSecond;
    #[inline]
    fn div(self, t: Seconds) -> MetresPerSecond {
        MetresPerSecond(self.0 / t.0)
    }
}

impl Mul<Seconds> for MetresPerSecond {
    type Output = Metres;
    #[inline]
    fn mul(self, t: Seconds) -> Metres {
        Metres(self.0 * t.0)
    }
}

impl MetresPerSecond {
    /// Speed in body lengths per second for a fish of length `body`.
    #[inline]
    pub fn in_body_lengths(self, body: Metres) -> f64 {
        self.0 / body.0
    }
}

impl Seconds {
    /// Builds a duration from milliseconds.
    #[inline]
    pub fn from_millis(ms: f64) -> Self {
        Self(ms / 1000.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn speed_is_distance_over_time() {
        let v = Metres(1.5) / Seconds(0.5);
        assert_eq!(v, MetresPerSecond(3.0));
        assert_eq!(v * Seconds(2.0), Metres(6.0));
        assert!((v.in_body_lengths(Metres(0.5)) - 6.0).abs() < 1e-12);
        assert_eq!(format!("{:.2}", Metres(1.0)), "1.00 m");
    }
}
