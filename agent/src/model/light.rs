//! The light head: from the scene tokens, the state of the traffic light that governs the
//! route ahead ([`LightClass`]), a [`super::classifier::TokenClassifier`].
//!
//! The hazard head names a light only while the expert brakes for it; this head asks the
//! tokens for the light itself, green and far ones included, so that the lamp, a few pixels of
//! a 320x96 frame, gets a gradient on every frame that has one (TransFuser++ and TCP-style
//! agents add such a label). Its label is the light ahead each stored frame records
//! (`ssrdrive_proto::dataset::LightAhead`); frames recorded before the label are left out of
//! its loss ([`crate::train::light`]). It is in the network, and in its checkpoints, when
//! [`super::config::SsrConfig::light_head`] says so.

use ssrdrive_proto::dataset::LightAhead;

/// How far ahead (free metres to the stop line) a light counts; a farther one is
/// [`LightClass::NoLight`], as the camera barely shows it.
pub const LIGHT_RANGE_M: f64 = 40.0;

/// The state of the light ahead: the head's classes, in logit order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LightClass {
    /// No light on the route within [`LIGHT_RANGE_M`].
    NoLight,
    /// Green.
    Green,
    /// Yellow.
    Yellow,
    /// Red.
    Red,
}

impl LightClass {
    /// Every class, in logit order.
    pub const ALL: [LightClass; 4] = [
        LightClass::NoLight,
        LightClass::Green,
        LightClass::Yellow,
        LightClass::Red,
    ];

    /// The class of a frame's light ahead.
    pub fn of(light: &LightAhead) -> Self {
        let within = |d: f64| d <= LIGHT_RANGE_M;
        match *light {
            LightAhead::Green { distance } if within(distance) => LightClass::Green,
            LightAhead::Yellow { distance } if within(distance) => LightClass::Yellow,
            LightAhead::Red { distance } if within(distance) => LightClass::Red,
            _ => LightClass::NoLight,
        }
    }

    /// The logit index.
    pub fn index(self) -> usize {
        self as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_light_counts_within_its_range() {
        assert_eq!(LightClass::of(&LightAhead::None), LightClass::NoLight);
        assert_eq!(
            LightClass::of(&LightAhead::Red { distance: 12.0 }),
            LightClass::Red
        );
        assert_eq!(
            LightClass::of(&LightAhead::Green { distance: 0.0 }),
            LightClass::Green
        );
        assert_eq!(
            LightClass::of(&LightAhead::Yellow { distance: 39.9 }),
            LightClass::Yellow
        );
        assert_eq!(
            LightClass::of(&LightAhead::Red { distance: 45.0 }),
            LightClass::NoLight
        );
        for (i, class) in LightClass::ALL.into_iter().enumerate() {
            assert_eq!(class.index(), i);
        }
    }
}
