//! The packed layout: where each chart's rectangle lies in the atlas, and the invariants every
//! layout keeps (non-empty rectangles, inside the atlas with their gutters, no overlap).

/// Where the charts went. Each rectangle's content is `width x height` texels at `(x, y)`; the
/// gutter surrounds it, so the padded rectangle is `(x - gutter, y - gutter)` of size
/// `(width + 2 gutter, height + 2 gutter)`.
///
/// Invariants (checked by [`Layout::validate`]): every content rectangle is non-empty, every
/// padded rectangle lies inside `width x height`, and no two padded rectangles overlap.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Layout {
    /// Atlas width in texels: the packed extent, not the side the packer was given.
    pub width: u32,
    /// Atlas height in texels.
    pub height: u32,
    /// Texels of padding on each side of every rectangle.
    pub gutter: u32,
    /// One rectangle per input size, in input order.
    pub rects: Vec<PackedRect>,
}

/// One chart's content rectangle in the atlas, gutter excluded.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PackedRect {
    /// Left edge in texels.
    pub x: u32,
    /// Top edge in texels.
    pub y: u32,
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
}

/// A broken [`Layout`] invariant.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum LayoutError {
    /// A rectangle has no area.
    #[error("rectangle {0} is empty")]
    Empty(usize),
    /// A padded rectangle leaves the atlas.
    #[error("rectangle {0} with its gutter leaves the atlas")]
    Outside(usize),
    /// Two padded rectangles share texels.
    #[error("rectangles {0} and {1} overlap with their gutters")]
    Overlap(usize, usize),
}

impl Layout {
    /// Checks every invariant listed on the type.
    pub fn validate(&self) -> Result<(), LayoutError> {
        let g = u64::from(self.gutter);
        // Padded rectangles as [x0, x1) x [y0, y1) in u64, so no sum overflows.
        let mut padded = Vec::with_capacity(self.rects.len());
        for (i, r) in self.rects.iter().enumerate() {
            if r.width == 0 || r.height == 0 {
                return Err(LayoutError::Empty(i));
            }
            let (x, y) = (u64::from(r.x), u64::from(r.y));
            let (x1, y1) = (x + u64::from(r.width) + g, y + u64::from(r.height) + g);
            if x < g || y < g || x1 > u64::from(self.width) || y1 > u64::from(self.height) {
                return Err(LayoutError::Outside(i));
            }
            padded.push((x - g, x1, y - g, y1, i));
        }
        // Sweep along x: only rectangles starting before one ends can overlap it.
        padded.sort_unstable();
        for (k, a) in padded.iter().enumerate() {
            for b in padded[k + 1..].iter().take_while(|b| b.0 < a.1) {
                if b.2 < a.3 && a.2 < b.3 {
                    return Err(LayoutError::Overlap(a.4.min(b.4), a.4.max(b.4)));
                }
            }
        }
        Ok(())
    }

    /// The padded rectangle of `rect` as `(x0, y0, x1, y1)`, end-exclusive.
    pub fn padded(&self, rect: &PackedRect) -> (u32, u32, u32, u32) {
        let g = self.gutter;
        (
            rect.x - g,
            rect.y - g,
            rect.x + rect.width + g,
            rect.y + rect.height + g,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn validate_catches_overlap_and_outside() {
        let mut layout = Layout {
            width: 10,
            height: 10,
            gutter: 1,
            rects: vec![
                PackedRect {
                    x: 1,
                    y: 1,
                    width: 3,
                    height: 3,
                },
                PackedRect {
                    x: 5,
                    y: 1,
                    width: 3,
                    height: 3,
                },
            ],
        };
        // Padded: [0,5) and [4,9) in x share column 4.
        assert_eq!(layout.validate(), Err(LayoutError::Overlap(0, 1)));
        layout.rects[1].x = 6;
        assert_eq!(layout.validate(), Ok(()));
        layout.rects[1].x = 7;
        // [6, 11) leaves the 10-wide atlas.
        assert_eq!(layout.validate(), Err(LayoutError::Outside(1)));
    }
}
