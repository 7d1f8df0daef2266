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

    /// The [`std::time::Duration`] of this many seconds, or an error for a negative, NaN, infinite
    /// or too large value (where `Duration::from_secs_f64` panics). Timers built from outside input
    /// (the configuration, a recording's frame rate) go through this.
    pub fn to_duration(self) -> Result<std::time::Duration, DurationError> {
        let d = std::time::Duration::try_from_secs_f64(self.0).map_err(|_| DurationError(self.0))?;
        // A timer adds the duration to `Instant::now()`: that must not overflow either (about 10^11 s
        // on common platforms; a century is far below it).
        if d > MAX_DURATION {
            return Err(DurationError(self.0));
        }
        Ok(d)
    }
}

/// Longest duration [`Seconds::to_duration`] gives: 100 years.
pub const MAX_DURATION: std::time::Duration = std::time::Duration::from_secs(100 * 365 * 86_400);

/// A number of seconds that is no duration: negative, NaN, infinite or over [`MAX_DURATION`].
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error("{0} s is not a duration (must be finite, >= 0 and at most 100 years)")]
pub struct DurationError(pub f64);

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

    #[test]
    fn durations_are_checked_not_panicking() {
        assert_eq!(Seconds(1.5).to_duration(), Ok(std::time::Duration::from_millis(1500)));
        assert_eq!(Seconds(0.0).to_duration(), Ok(std::time::Duration::ZERO));
        for bad in [-1.0, f64::NAN, f64::INFINITY, 1e20, 1e300] {
            assert!(Seconds(bad).to_duration().is_err(), "{bad}");
        }
        assert!(Seconds(1e-300).to_duration().is_ok());
    }
}
