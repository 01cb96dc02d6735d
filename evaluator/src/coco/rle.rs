//! COCO's run-length encoding of binary masks, with the semantics of pycocotools' `maskApi.c`
//! (the C core the toolkit's COCOeval calls), so that areas, boxes and IoUs agree bit for bit.
//!
//! A mask of `height x width` pixels is read column by column (column-major, "Fortran"
//! order); `counts` alternates runs of 0s and 1s, starting with 0s (a mask whose first pixel
//! is set starts with a run of length 0). Result files give the counts either as a JSON list,
//! as bop_toolkit's `binary_mask_to_rle` writes them, or as pycocotools' compressed string
//! (6 bits a character, ASCII 48..111, each count after the third as the difference to the
//! count two before it).
//!
//! maskApi trusts its input: counts that do not add up to `height * width` make its decoder
//! overrun the mask and its IoU loop run forever. Here they are refused when the RLE is made,
//! so every [`Rle`] is consistent and every function below terminates.

/// A mask in run-length encoding; always consistent (the counts add up to its pixels).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Rle {
    height: u32,
    width: u32,
    counts: Vec<u32>,
}

/// The longest value of a compressed string, in characters. maskApi decodes with `int` shifts
/// (`(c & 0x1f) << 5*k`), which overflow past six characters; six cover every count difference
/// of an image of up to 2^29 pixels, so refusing longer ones loses nothing and keeps the
/// decoding exact.
const MAX_CHARS_PER_VALUE: usize = 6;

impl Rle {
    /// An RLE from its counts (the list form); the counts must add up to `height * width`.
    pub fn from_counts(height: u32, width: u32, counts: Vec<u32>) -> Result<Rle, String> {
        if height == 0 || width == 0 {
            return Err(format!("size {height} x {width} has no pixel"));
        }
        let pixels = u64::from(height) * u64::from(width);
        if pixels > u64::from(u32::MAX) {
            return Err(format!(
                "size {height} x {width} has more pixels than an RLE can count"
            ));
        }
        let sum: u64 = counts.iter().map(|&c| u64::from(c)).sum();
        if sum != pixels {
            return Err(format!(
                "the counts add up to {sum} pixels, not {height} x {width} = {pixels}"
            ));
        }
        Ok(Rle {
            height,
            width,
            counts,
        })
    }

    /// Decodes pycocotools' compressed string (maskApi's `rleFrString`).
    pub fn from_compressed(s: &str, height: u32, width: u32) -> Result<Rle, String> {
        let bytes = s.as_bytes();
        let mut counts: Vec<u32> = Vec::with_capacity(bytes.len() / 2 + 1);
        let mut p = 0;
        while p < bytes.len() {
            let start = p;
            let mut x: i64 = 0;
            let mut k = 0;
            loop {
                let Some(&b) = bytes.get(p) else {
                    return Err(format!(
                        "the compressed counts end inside a value (at character {start})"
                    ));
                };
                if !(48..=111).contains(&b) {
                    return Err(format!(
                        "character {p} of the compressed counts is {:?}, outside '0'..='o'",
                        char::from(b)
                    ));
                }
                let c = i64::from(b) - 48;
                x |= (c & 0x1f) << (5 * k);
                p += 1;
                k += 1;
                if k > MAX_CHARS_PER_VALUE {
                    return Err(format!(
                        "the value at character {start} of the compressed counts is longer \
                         than {MAX_CHARS_PER_VALUE} characters"
                    ));
                }
                if c & 0x20 == 0 {
                    if c & 0x10 != 0 {
                        x |= -1i64 << (5 * k);
                    }
                    break;
                }
            }
            let m = counts.len();
            if m > 2 {
                x += i64::from(counts[m - 2]);
            }
            let value = u32::try_from(x).map_err(|_| {
                format!("count {m} of the compressed counts is {x}, not a pixel count")
            })?;
            counts.push(value);
        }
        Rle::from_counts(height, width, counts)
    }

    /// Encodes a mask given column by column (maskApi's `rleEncode`).
    pub fn encode(column_major: &[bool], height: u32, width: u32) -> Result<Rle, String> {
        let pixels = u64::from(height) * u64::from(width);
        if column_major.len() as u64 != pixels {
            return Err(format!(
                "a {height} x {width} mask has {pixels} pixels, not {}",
                column_major.len()
            ));
        }
        let mut counts = Vec::new();
        let mut previous = false;
        let mut run = 0u32;
        for &v in column_major {
            if v != previous {
                counts.push(run);
                run = 0;
                previous = v;
            }
            run += 1;
        }
        counts.push(run);
        Rle::from_counts(height, width, counts)
    }

    /// Encodes a mask given row by row, as images are stored.
    pub fn encode_row_major(row_major: &[bool], height: u32, width: u32) -> Result<Rle, String> {
        let (h, w) = (height as usize, width as usize);
        if row_major.len() != h * w {
            return Err(format!(
                "a {height} x {width} mask has {} pixels, not {}",
                h * w,
                row_major.len()
            ));
        }
        let column_major: Vec<bool> = (0..w)
            .flat_map(|x| (0..h).map(move |y| (y, x)))
            .map(|(y, x)| row_major[y * w + x])
            .collect();
        Rle::encode(&column_major, height, width)
    }

    /// The mask, column by column (maskApi's `rleDecode`).
    pub fn decode(&self) -> Vec<bool> {
        let mut mask = Vec::with_capacity(self.height as usize * self.width as usize);
        let mut v = false;
        for &c in &self.counts {
            mask.extend(std::iter::repeat_n(v, c as usize));
            v = !v;
        }
        mask
    }

    /// pycocotools' compressed string (maskApi's `rleToString`).
    pub fn to_compressed(&self) -> String {
        let mut s = String::with_capacity(self.counts.len() * 2);
        for (i, &c) in self.counts.iter().enumerate() {
            let mut x = i64::from(c);
            if i > 2 {
                x -= i64::from(self.counts[i - 2]);
            }
            loop {
                let mut ch = x & 0x1f;
                x >>= 5;
                let more = if ch & 0x10 != 0 { x != -1 } else { x != 0 };
                if more {
                    ch |= 0x20;
                }
                s.push(char::from((ch + 48) as u8));
                if !more {
                    break;
                }
            }
        }
        s
    }

    pub fn height(&self) -> u32 {
        self.height
    }

    pub fn width(&self) -> u32 {
        self.width
    }

    pub fn counts(&self) -> &[u32] {
        &self.counts
    }

    /// The number of set pixels (maskApi's `rleArea`).
    pub fn area(&self) -> u32 {
        self.counts.iter().skip(1).step_by(2).sum()
    }

    /// The bounding box `[x, y, width, height]` (maskApi's `rleToBbox`), with its quirk: a run
    /// of set pixels that wraps into the next column makes the box span the whole height.
    pub fn to_bbox(&self) -> [f64; 4] {
        let (h, w) = (self.height, self.width);
        let m = self.counts.len() / 2 * 2;
        if m == 0 {
            return [0.0; 4];
        }
        let (mut xs, mut ys, mut xe, mut ye) = (w, h, 0u32, 0u32);
        let (mut cc, mut xp) = (0u32, 0u32);
        for j in 0..m {
            cc = cc.wrapping_add(self.counts[j]);
            let t = cc.wrapping_sub((j % 2) as u32);
            let y = t % h;
            let x = (t - y) / h;
            if j % 2 == 0 {
                xp = x;
            } else if xp < x {
                ys = 0;
                ye = h - 1;
            }
            xs = xs.min(x);
            xe = xe.max(x);
            ys = ys.min(y);
            ye = ye.max(y);
        }
        [
            f64::from(xs),
            f64::from(ys),
            f64::from(xe.wrapping_sub(xs).wrapping_add(1)),
            f64::from(ye.wrapping_sub(ys).wrapping_add(1)),
        ]
    }
}

/// The IoU of a detection's mask with a ground-truth mask (maskApi's `rleIou`): for a crowd
/// ground truth the union is the detection's area alone; masks of different sizes give -1
/// (when their boxes overlap, else 0), which no threshold accepts.
pub fn rle_iou(dt: &Rle, gt: &Rle, iscrowd: bool) -> f64 {
    let o = bbox_iou(&dt.to_bbox(), &gt.to_bbox(), iscrowd);
    if o <= 0.0 {
        return o;
    }
    if dt.height != gt.height || dt.width != gt.width {
        return -1.0;
    }
    let (a_counts, b_counts) = (&dt.counts, &gt.counts);
    let (mut ca, mut cb) = (a_counts[0], b_counts[0]);
    let (mut va, mut vb) = (false, false);
    let (mut a, mut b) = (1, 1);
    let (mut inter, mut union) = (0u32, 0u32);
    loop {
        let c = ca.min(cb);
        if va || vb {
            union = union.wrapping_add(c);
            if va && vb {
                inter = inter.wrapping_add(c);
            }
        }
        ca -= c;
        if ca == 0 && a < a_counts.len() {
            ca = a_counts[a];
            a += 1;
            va = !va;
        }
        cb -= c;
        if cb == 0 && b < b_counts.len() {
            cb = b_counts[b];
            b += 1;
            vb = !vb;
        }
        if ca == 0 && cb == 0 {
            break;
        }
    }
    if inter == 0 {
        union = 1;
    } else if iscrowd {
        union = dt.area();
    }
    f64::from(inter) / f64::from(union)
}

/// The IoU of two boxes `[x, y, width, height]` (maskApi's `bbIou`), the crowd rule as for
/// masks.
pub fn bbox_iou(dt: &[f64; 4], gt: &[f64; 4], iscrowd: bool) -> f64 {
    let ga = gt[2] * gt[3];
    let da = dt[2] * dt[3];
    let w = (dt[2] + dt[0]).min(gt[2] + gt[0]) - dt[0].max(gt[0]);
    if w <= 0.0 {
        return 0.0;
    }
    let h = (dt[3] + dt[1]).min(gt[3] + gt[1]) - dt[1].max(gt[1]);
    if h <= 0.0 {
        return 0.0;
    }
    let i = w * h;
    let u = if iscrowd { da } else { da + ga - i };
    i / u
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compressed_round_trip_and_refusals() {
        let rle = Rle::from_counts(4, 3, vec![0, 2, 3, 1, 6]).unwrap();
        let s = rle.to_compressed();
        assert_eq!(Rle::from_compressed(&s, 4, 3).unwrap(), rle);
        assert!(Rle::from_counts(4, 3, vec![1, 2]).is_err());
        assert!(Rle::from_compressed("1 ", 4, 3).is_err());
        // A continuation bit on the last character: the value never ends.
        assert!(Rle::from_compressed("0P", 4, 3).is_err());
    }

    #[test]
    fn encode_decode_area() {
        let mask = [false, true, true, false, false, true];
        let rle = Rle::encode(&mask, 3, 2).unwrap();
        assert_eq!(rle.counts(), &[1, 2, 2, 1]);
        assert_eq!(rle.decode(), mask);
        assert_eq!(rle.area(), 3);
        let row = Rle::encode_row_major(&[true, false, false, false], 2, 2).unwrap();
        assert_eq!(row.counts(), &[0, 1, 3]);
    }
}
