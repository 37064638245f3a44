//! Pieces of the self-contained HTML page: escaping, PNG data URIs, the page frame with its
//! self-check script.

use std::io::Cursor;

use anyhow::Context as _;
use base64::Engine as _;

/// Escapes text for HTML element content and attribute values.
#[must_use]
pub fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            _ => out.push(c),
        }
    }
    out
}

/// An RGB image as a `data:image/png;base64,…` URI.
///
/// # Errors
/// The buffer does not hold `width * height` RGB pixels, or PNG encoding fails.
pub fn png_data_uri(rgb: image::RgbImage) -> anyhow::Result<String> {
    let mut png = Vec::new();
    image::DynamicImage::ImageRgb8(rgb)
        .write_to(&mut Cursor::new(&mut png), image::ImageFormat::Png)
        .context("encoding a PNG for the report")?;
    Ok(format!(
        "data:image/png;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(png)
    ))
}

/// An `<img>` of a PNG data URI with alternative text.
#[must_use]
pub fn img(uri: &str, alt: &str, class: &str) -> String {
    format!(r#"<img class="{class}" src="{uri}" alt="{}">"#, escape(alt))
}

/// A plot (inline SVG document) in a figure the page's self-check measures (`data-plot`).
#[must_use]
pub fn plot(name: &str, svg: &str, caption: &str) -> String {
    format!(
        r#"<figure class="plot" data-plot="{name}">{svg}<figcaption>{}</figcaption></figure>"#,
        escape(caption)
    )
}

/// The stylesheet of the page.
const STYLE: &str = r"
body { font-family: 'DejaVu Sans', sans-serif; margin: 16px 24px; color: #222; max-width: 1500px; }
svg text { font-family: 'DejaVu Sans', sans-serif; }
h1 { font-size: 22px; } h2 { font-size: 18px; border-bottom: 1px solid #ccc; margin-top: 28px; }
table { border-collapse: collapse; font-size: 13px; }
td, th { border: 1px solid #ddd; padding: 2px 8px; text-align: left; }
figure { display: inline-block; margin: 6px; vertical-align: top; }
figcaption { font-size: 12px; color: #555; max-width: 640px; }
.gallery td { vertical-align: top; border: none; }
.gallery img { display: block; }
.depth { image-rendering: pixelated; }
.note { color: #8a5a00; }
";

/// Records load errors and the position of every plot into `document.title`, which a headless
/// browser reads back with `--dump-dom`: `visnav-report-ok | plots name,x,y,w,h …` or
/// `visnav-report-errors: … | plots …`.
const SELF_CHECK: &str = r"
(function () {
  var errors = [];
  window.addEventListener('error', function (e) {
    var t = e.target;
    if (t && t !== window && t.tagName) {
      errors.push('cannot load ' + t.tagName.toLowerCase() + ' ' + (t.alt || ''));
    } else {
      errors.push('script error ' + e.message);
    }
  }, true);
  window.addEventListener('load', function () {
    var imgs = document.images;
    for (var i = 0; i < imgs.length; i++) {
      if (!imgs[i].complete || imgs[i].naturalWidth === 0) {
        errors.push('image not decoded: ' + imgs[i].alt);
      }
    }
    var regions = [];
    var plots = document.querySelectorAll('[data-plot] > svg');
    for (var k = 0; k < plots.length; k++) {
      var r = plots[k].getBoundingClientRect();
      var name = plots[k].parentNode.getAttribute('data-plot');
      if (r.width < 10 || r.height < 10) { errors.push('plot not laid out: ' + name); }
      regions.push([name, Math.round(r.left + window.scrollX), Math.round(r.top + window.scrollY),
        Math.round(r.width), Math.round(r.height)].join(','));
    }
    document.title = (errors.length ? 'visnav-report-errors: ' + errors.join('; ') : 'visnav-report-ok')
      + ' | plots ' + regions.join(' ');
  });
})();
";

/// The whole page around `body`.
#[must_use]
pub fn page(title: &str, body: &str) -> String {
    format!(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{t}</title>\
         <style>{STYLE}</style><script>{SELF_CHECK}</script></head>\n<body>\n{body}\n</body></html>\n",
        t = escape(title)
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escaping_and_data_uris() {
        assert_eq!(
            escape(r#"<a href="x">&'"#),
            "&lt;a href=&quot;x&quot;&gt;&amp;&#39;"
        );
        let uri = png_data_uri(image::RgbImage::from_pixel(3, 2, image::Rgb([1, 2, 3]))).unwrap();
        let b64 = uri.strip_prefix("data:image/png;base64,").unwrap();
        let png = base64::engine::general_purpose::STANDARD
            .decode(b64)
            .unwrap();
        let back = image::load_from_memory(&png).unwrap().to_rgb8();
        assert_eq!(back.dimensions(), (3, 2));
        assert_eq!(back.get_pixel(2, 1).0, [1, 2, 3]);
        let p = page("a<b", "<p>x</p>");
        assert!(p.contains("<title>a&lt;b</title>") && p.contains("visnav-report-ok"));
        assert!(
            !p.contains("http://") && !p.contains("https://"),
            "no network references"
        );
    }
}
