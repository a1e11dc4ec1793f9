//! The replay drawing: one scene on a canvas (the reference path, each
//! robot's trail and oriented triangle, the leader links, and with a safety
//! filter each robot's safety disc and the obstacles), drawn from what a
//! driver hands it each frame. One source for two pages: `report.html`'s
//! replay ([`crate::html`], driven by a recorded run) and the fleet's live
//! dashboard (`echelon-fleet`'s `collector::dashboard`, driven by the
//! robots' states as they arrive).
//!
//! [`drawing`] is the script (`assets/replay-draw.js`, with
//! `assets/replay-safety.js` inserted for a scene with a safety filter): it
//! defines `echelonDrawing(canvas, scene)`, whose contract its comments
//! state. [`STYLE`] is the pages' style sheet (the colours it draws with are
//! its `--ink` and `--muted`), [`agent_color`] each agent's colour.

use crate::figure::palette;

/// The style sheet of the pages that draw with [`drawing`].
pub const STYLE: &str = include_str!("../assets/report.css");
/// `echelonDrawing`, without the safety drawing.
const DRAWING: &str = include_str!("../assets/replay-draw.js");
/// Drawing the safety discs: inserted into [`DRAWING`] for a scene with a
/// safety filter, before [`SAFETY_FN_ANCHOR`], and called before
/// [`SAFETY_CALL_ANCHOR`].
const SAFETY: &str = include_str!("../assets/replay-safety.js");
const SAFETY_FN_ANCHOR: &str = "  function draw(f) {\n";
const SAFETY_CALL_ANCHOR: &str = "    // Robots: oriented triangles, one filled path per colour.\n";

/// The drawing's script: `echelonDrawing`, with the safety drawing when
/// `safety` (the scene then needs its `safety` and each frame its `action`).
pub fn drawing(safety: bool) -> String {
    if !safety {
        return DRAWING.to_owned();
    }
    DRAWING
        .replacen(SAFETY_FN_ANCHOR, &format!("{SAFETY}{SAFETY_FN_ANCHOR}"), 1)
        .replacen(
            SAFETY_CALL_ANCHOR,
            &format!("    if (safety) drawSafety(f, muted);\n{SAFETY_CALL_ANCHOR}"),
            1,
        )
}

/// Agent `i`'s (from 0) colour, `#RRGGBB`: the figures' series colours.
pub fn agent_color(i: usize) -> String {
    palette::series(i).hex()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_safety_script_finds_its_anchors_once() {
        assert_eq!(DRAWING.matches(SAFETY_FN_ANCHOR).count(), 1);
        assert_eq!(DRAWING.matches(SAFETY_CALL_ANCHOR).count(), 1);
        assert_eq!(drawing(false), DRAWING);
        assert!(!DRAWING.contains("drawSafety"));
        let with = drawing(true);
        assert_eq!(with.matches("function drawSafety(").count(), 1);
        assert_eq!(with.matches("drawSafety(f, muted);").count(), 1);
        assert!(
            with.find("function drawSafety(") < with.find("function draw(f) {")
                && with.find("drawSafety(f, muted);") < with.find(SAFETY_CALL_ANCHOR)
        );
    }
}
