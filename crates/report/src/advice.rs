//! Findings in the vocabulary's words as HTML: a card per finding (its severity, what is wrong
//! with its size, how sure, what it does to control, what to do, and a link to its evidence),
//! and a compact line of each for a table, coloured by severity with the page's `sev-*` styles.
//!
//! Not here: the words themselves ([`vb_core::vocabulary`]).

use std::fmt::Write;

use super::esc;
use vb_core::vocabulary::{capitalised, Advice, Severity};

/// The class that colours an element by `severity` (`sev-high`, ...; `sev-none` without one).
pub fn class(severity: Option<Severity>) -> String {
    format!("sev-{}", severity.map_or("none", Severity::name))
}

/// A card per finding, highest priority first; each links to its evidence at
/// `evidence` + the effect's vocabulary name (`#finding-backlash`).
pub fn cards(list: &[Advice], evidence: &str) -> String {
    let mut h = String::from("<div class=\"advice\">");
    for a in list {
        let _ = write!(
            h,
            "<div class=\"card {}\"><b>{}</b> · <b>{}</b> {} <small>({})</small><br>\
             For control: {}.<br>To do: {}. <a href=\"{}{}\">evidence</a></div>",
            class(Some(a.severity)),
            capitalised(a.severity.name()),
            esc(&a.name),
            esc(&a.does),
            esc(&a.sure),
            esc(&a.control),
            esc(&a.action),
            esc(evidence),
            esc(&a.effect)
        );
    }
    h.push_str("</div>");
    h
}

/// One line per finding for a table cell: `lost motion (backlash): loses 5.83 % ... of travel
/// on every reversal. To do: check the packing ...`, the action shortened to its first clause.
pub fn lines(list: &[Advice]) -> String {
    let items: Vec<String> = (list.iter())
        .map(|a| {
            let action = a.action.split(';').next().unwrap_or(&a.action);
            format!(
                "<span class=\"{}\"><b>{}</b>: {}. <i>To do:</i> {}.</span>",
                class(Some(a.severity)),
                esc(&a.name),
                esc(&a.does),
                esc(action)
            )
        })
        .collect();
    items.join("<br>")
}

#[cfg(test)]
mod tests {
    use super::*;
    use vb_core::model::composed::{Effect, Size};

    #[test]
    fn a_card_links_its_evidence_and_is_coloured() {
        let size = Size {
            name: "friction_band_pct",
            unit: "%",
            value: 5.83,
            low: 5.69,
            high: 5.86,
            worth: 19.4,
            worth_low: 19.0,
        };
        let a = Advice::of(Effect::Backlash, &size);
        let h = cards(std::slice::from_ref(&a), "#finding-");
        assert!(h.contains("class=\"card sev-high\"") && h.contains("href=\"#finding-backlash\""));
        assert!(h.contains("loses 5.83 % (5.69-5.86) of travel on every reversal"));
        let l = lines(&[a]);
        assert!(
            l.contains("<i>To do:</i> check the packing and the linkage"),
            "{l}"
        );
        assert!(!l.contains("tighten"), "{l}");
    }
}
