//! Crops the same region out of images (PNG, JPEG or colour EXR) and writes
//! each, upscaled by pixel repetition, as a PNG: the README's anti-aliasing
//! montage.
//!
//! ```sh
//! cargo run --release --example crop -- X Y W H SCALE OUT_DIR IMAGE...
//! ```
//!
//! writes `OUT_DIR/<image stem>.png` for every image.

use std::path::{Path, PathBuf};

use snell::film::metrics::RgbImage;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    anyhow::ensure!(
        args.len() >= 7,
        "usage: crop X Y W H SCALE OUT_DIR IMAGE..."
    );
    let num = |i: usize| -> anyhow::Result<u32> { Ok(args[i].parse()?) };
    let (x0, y0, w, h, scale) = (num(0)?, num(1)?, num(2)?, num(3)?, num(4)?);
    anyhow::ensure!(w > 0 && h > 0 && scale > 0, "empty crop");
    let out_dir = PathBuf::from(&args[5]);
    for input in &args[6..] {
        let img = RgbImage::read(Path::new(input))?;
        anyhow::ensure!(
            x0 + w <= img.width && y0 + h <= img.height,
            "{input}: the crop does not fit in {}x{}",
            img.width,
            img.height
        );
        let (ow, oh) = (w * scale, h * scale);
        let mut rgb = Vec::with_capacity((ow * oh * 3) as usize);
        for y in 0..oh {
            for x in 0..ow {
                let c = img.pixels[((y0 + y / scale) * img.width + x0 + x / scale) as usize];
                rgb.extend(c.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8));
            }
        }
        let stem = Path::new(input)
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "crop".into());
        let out = out_dir.join(format!("{stem}.png"));
        snell::film::write_png_rgb(&out, ow, oh, &rgb)?;
        println!("{}", out.display());
    }
    Ok(())
}
