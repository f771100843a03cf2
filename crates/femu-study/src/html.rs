//! A self-contained HTML page (figures embedded as data URIs, no script, no external resource):
//! the frame of the run report ([`crate::report`]) and of other reports built on it (the
//! population report of `femu batch collect`).

use base64::Engine;
use std::fmt::Write as _;
use std::path::Path;

/// `s` escaped for HTML text and attribute values.
pub fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// `x` with 4 significant digits.
pub fn g(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return format!("{x}");
    }
    let a = x.abs();
    if (1e-3..1e5).contains(&a) {
        let d = (3 - a.log10().floor() as i32).max(0) as usize;
        format!("{x:.d$}")
    } else {
        format!("{x:.3e}")
    }
}

/// A page being written: its body, the table of contents (one entry per `h2`) and the figure
/// count (figures are numbered).
#[derive(Default)]
pub struct Page {
    pub body: String,
    toc: Vec<(String, String)>,
    figures: usize,
}

impl Page {
    /// A section title (listed in the table of contents).
    pub fn h2(&mut self, title: &str) {
        let id = format!("s{}", self.toc.len() + 1);
        let _ = write!(self.body, "<h2 id=\"{id}\">{}</h2>", esc(title));
        self.toc.push((id, title.to_string()));
    }

    pub fn h3(&mut self, title: &str) {
        let _ = write!(self.body, "<h3>{}</h3>", esc(title));
    }

    /// A paragraph of trusted HTML.
    pub fn p(&mut self, html: &str) {
        let _ = write!(self.body, "<p>{html}</p>");
    }

    /// A table of text cells (escaped).
    pub fn table(&mut self, header: &[&str], rows: &[Vec<String>]) {
        self.body.push_str("<table><thead><tr>");
        for h in header {
            let _ = write!(self.body, "<th>{}</th>", esc(h));
        }
        self.body.push_str("</tr></thead><tbody>");
        for r in rows {
            self.body.push_str("<tr>");
            for c in r {
                let _ = write!(self.body, "<td>{}</td>", esc(c));
            }
            self.body.push_str("</tr>");
        }
        self.body.push_str("</tbody></table>");
    }

    /// Embeds a PNG with a numbered caption; nothing if the file is missing.
    pub fn figure(&mut self, path: &Path, caption: &str) -> bool {
        let Ok(bytes) = std::fs::read(path) else {
            return false;
        };
        self.figures += 1;
        let data = base64::engine::general_purpose::STANDARD.encode(bytes);
        let _ = write!(
            self.body,
            "<figure><img alt=\"{}\" src=\"data:image/png;base64,{data}\"><figcaption>Figure {}. {}</figcaption></figure>",
            esc(caption),
            self.figures,
            esc(caption)
        );
        true
    }

    /// The whole page, titled `title` (the browser's tab).
    pub fn finish(self, title: &str) -> String {
        let mut toc = String::from("<nav><b>Contents</b><ol>");
        for (id, t) in &self.toc {
            let _ = write!(toc, "<li><a href=\"#{id}\">{}</a></li>", esc(t));
        }
        toc.push_str("</ol></nav>");
        format!(
            "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
             <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\
             <title>{}</title><style>{CSS}</style></head><body>{toc}<main>{}</main></body></html>\n",
            esc(title),
            self.body
        )
    }
}

const CSS: &str = "body{font-family:system-ui,sans-serif;margin:0;display:flex;color:#222}\
nav{position:sticky;top:0;align-self:flex-start;width:220px;padding:1em;font-size:90%}\
main{max-width:1100px;min-width:0;flex:1;padding:1em 2em}h1{font-size:1.6em}h2{border-bottom:1px solid #ccc;margin-top:2em}\
table{border-collapse:collapse;margin:0.5em 0;font-size:85%;max-width:100%}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}\
th{background:#f2f2f2}td:first-child{text-align:left}figure{margin:1em 0}img{max-width:100%;border:1px solid #eee}\
figcaption{font-size:90%;color:#555}pre{background:#f7f7f7;padding:1em;overflow:auto;font-size:85%}\
.bad{color:#b00}";
