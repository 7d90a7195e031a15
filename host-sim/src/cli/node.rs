//! The node board on the command line: `--node NAME` ([`parse_node`]), a SceneImage's fit
//! against the board's scene banks (`links info --node`, [`fit_lines`]) and the refusal of an
//! image no bank holds before anything is sent ([`check_fits`]).

use std::fmt;

use links_core::board::{Fit, NodeBoard};

use super::CliError;

/// A `--node` name no board has.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnknownNode(pub String);

impl fmt::Display for UnknownNode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let known: Vec<&str> = NodeBoard::ALL.iter().map(|b| b.name).collect();
        write!(
            f,
            "unknown node board '{}'; known: {}",
            self.0,
            known.join(", ")
        )
    }
}

impl std::error::Error for UnknownNode {}

/// `--node NAME`: a known board (ASCII case ignored), or an error naming the known ones.
pub fn parse_node(name: &str) -> Result<NodeBoard, UnknownNode> {
    NodeBoard::named(name).ok_or_else(|| UnknownNode(name.to_string()))
}

/// `n` with a comma between groups of three digits (`187,136`).
pub fn grouped(n: usize) -> String {
    let digits = n.to_string();
    let mut out = String::with_capacity(digits.len() + digits.len() / 3);
    for (i, c) in digits.chars().enumerate() {
        if i > 0 && (digits.len() - i).is_multiple_of(3) {
            out.push(',');
        }
        out.push(c);
    }
    out
}

/// `Ok` when a SceneImage of `bytes` bytes fits the bank of frame 0 (the one a single frame
/// uses) of `node`; otherwise [`CliError::DoesNotFit`] naming `what` (the scene or image
/// file) and both sizes.
pub fn check_fits(what: &str, bytes: usize, node: &NodeBoard) -> Result<(), CliError> {
    let bank = node.bank(0);
    if bytes <= bank {
        return Ok(());
    }
    Err(CliError::DoesNotFit {
        what: what.to_string(),
        bytes,
        node: node.name,
        bank,
    })
}

/// The lines `links info --node` adds: each bank's size and the bytes free or over, then the
/// verdict ([`Fit::describe`]).
pub fn fit_lines(bytes: usize, node: &NodeBoard) -> Vec<String> {
    let mut lines = vec![format!("  node {}: scene banks", node.name)];
    for (which, bank) in ["even frames", "odd frames"].iter().zip(node.scene_banks) {
        let left = if bytes <= bank {
            format!("{} bytes free", grouped(bank - bytes))
        } else {
            format!("{} bytes over", grouped(bytes - bank))
        };
        lines.push(format!(
            "    {which:<12} {:>10} bytes: {left}",
            grouped(bank)
        ));
    }
    let fit = node.fit(bytes);
    lines.push(format!("  {}: {}", node.name, fit.describe()));
    if fit == Fit::OneBank {
        lines.push(
            "  (the next frame's scene cannot be broadcast while this one renders)".to_string(),
        );
    }
    lines
}

#[cfg(test)]
mod tests {
    use super::*;
    use links_core::board::Memory;

    fn board() -> NodeBoard {
        NodeBoard {
            name: "t",
            sram: 0,
            ccm: 0,
            link_banks: 0,
            scene_banks: [61_440, 24_576],
            odd_bank_in: Memory::Ccm,
        }
    }

    #[test]
    fn grouped_puts_commas_every_three_digits() {
        let g: Vec<String> = [0, 999, 1000, 61_440, 187_136, 1_234_567]
            .into_iter()
            .map(grouped)
            .collect();
        assert_eq!(g, ["0", "999", "1,000", "61,440", "187,136", "1,234,567"]);
    }

    #[test]
    fn unknown_boards_are_refused_with_the_known_ones() {
        assert_eq!(parse_node("F407"), Ok(NodeBoard::F407));
        assert_eq!(parse_node("f207"), Ok(NodeBoard::F207));
        assert_eq!(parse_node("g0b1"), Ok(NodeBoard::G0B1));
        assert_eq!(
            parse_node("f429").unwrap_err().to_string(),
            "unknown node board 'f429'; known: f407, f207, g0b1"
        );
    }

    #[test]
    fn too_big_an_image_is_refused_naming_both_sizes() {
        assert!(check_fits("a.ron", 61_440, &board()).is_ok());
        let e = check_fits("scenes/photo2.ron", 187_136, &board()).unwrap_err();
        assert_eq!(
            e.to_string(),
            "scenes/photo2.ron: SceneImage 187,136 bytes does not fit the t node's scene bank (61,440 bytes)"
        );
    }

    #[test]
    fn fit_lines_give_each_bank_and_the_verdict() {
        assert_eq!(
            fit_lines(30_000, &board()),
            [
                "  node t: scene banks",
                "    even frames      61,440 bytes: 31,440 bytes free",
                "    odd frames       24,576 bytes: 5,424 bytes over",
                "  t: fits one bank (single frames only)",
                "  (the next frame's scene cannot be broadcast while this one renders)",
            ]
        );
        assert_eq!(fit_lines(1_000, &board())[3], "  t: fits two banks");
        assert_eq!(fit_lines(70_000, &board())[3], "  t: does not fit");
    }
}
