//! A depth map as the depth fit and the fish's depth read it, whatever it came from.

use super::MapKind;
use crate::geometry::Pixel;

/// A depth map as the pipeline samples it: the network's relative inverse depth, or a map swapped in.
pub trait DepthGrid {
    /// What the values are: relative inverse depth (needs the metric fit, eq. 1-2) or metres.
    fn kind(&self) -> MapKind;
    /// The value at `px` read with the map's point window (a small median).
    fn point(&self, px: Pixel) -> Option<f64>;
    /// The single map value nearest `px` (for box quantiles).
    fn grid(&self, px: Pixel) -> Option<f64>;
}
