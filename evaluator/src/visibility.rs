//! Visibility of a rendered object surface in a test depth image (paper, section 2.2).
//! Two variants exist and both are in use: the ECCV'18 paper's, where missing depth hides the
//! object, and bop_toolkit's since 2019, where missing depth counts as visible so that shiny
//! objects the sensor does not see can still be evaluated.

use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum VisibMode {
    /// Visible where the test image has depth and the model is at most `delta` behind it.
    Bop18,
    /// Visible where the model is at most `delta` behind the test image or the test image has no depth.
    Bop19,
}

impl VisibMode {
    pub fn name(self) -> &'static str {
        match self {
            VisibMode::Bop18 => "bop18",
            VisibMode::Bop19 => "bop19",
        }
    }
}

impl std::str::FromStr for VisibMode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "bop18" => Ok(VisibMode::Bop18),
            "bop19" => Ok(VisibMode::Bop19),
            other => Err(format!(
                "unknown visibility mode `{other}` (bop18 or bop19)"
            )),
        }
    }
}

/// Whether a model pixel at distance `d_model` is visible over a test pixel at `d_test`
/// (both distances from the camera centre, 0 = none). The difference is taken in float32 like
/// bop_toolkit, which decides pixels lying exactly `delta` behind the surface.
#[inline(always)]
pub fn visible(mode: VisibMode, d_test: f64, d_model: f64, delta: f32) -> bool {
    // `&` and `|`, not `&&` and `||`: no branch, so that loops over pixels run several at once.
    let behind = d_model as f32 - d_test as f32;
    match mode {
        VisibMode::Bop18 => (d_test > 0.0) & (d_model > 0.0) & (behind <= delta),
        VisibMode::Bop19 => (d_model > 0.0) & ((behind <= delta) | (d_test == 0.0)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn missing_depth_hides_in_bop18_and_shows_in_bop19() {
        assert!(!visible(VisibMode::Bop18, 0.0, 500.0, 15.0));
        assert!(visible(VisibMode::Bop19, 0.0, 500.0, 15.0));
    }

    #[test]
    fn occluded_pixels_are_invisible_in_both_modes() {
        for mode in [VisibMode::Bop18, VisibMode::Bop19] {
            assert!(visible(mode, 500.0, 515.0, 15.0));
            assert!(!visible(mode, 500.0, 515.5, 15.0));
            assert!(visible(mode, 500.0, 400.0, 15.0));
            assert!(!visible(mode, 500.0, 0.0, 15.0));
        }
    }
}
