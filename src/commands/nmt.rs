//! `canmotion nmt`: send one NMT node-control frame (`000#[cs][node]`), as `cansend` would.

use super::ToolError;
use super::args::{NmtCommand, NmtTarget};
use crate::bus::{Bus, Filter, Frame};
use crate::canopen::cob;

/// The NMT frame for `command` to `target`: `000#0105` starts node 5, `000#8200` resets the
/// communication of every node.
pub fn frame(command: NmtCommand, target: NmtTarget) -> Frame {
    Frame::new(cob::NMT, &[command.cs(), target.byte()]).expect("an NMT frame is valid")
}

/// Send `command` to `target` on `bus`; the frame sent. NMT has no answer: watch the heartbeats
/// (`canmotion monitor`) or `canmotion scan` to see the effect.
pub fn send(bus: &Bus, command: NmtCommand, target: NmtTarget) -> Result<Frame, ToolError> {
    // The port only sends; its filter keeps it from buffering the bus's traffic.
    let mut port = bus.open(&[Filter::exact(cob::NMT)])?;
    let f = frame(command, target);
    port.send(&f)?;
    Ok(f)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::commands::Node;

    #[test]
    fn frames_follow_the_checklist() {
        assert_eq!(
            frame(NmtCommand::Start, NmtTarget::Node(Node(5))).to_string(),
            "000#0105"
        );
        assert_eq!(
            frame(NmtCommand::ResetCommunication, NmtTarget::All).to_string(),
            "000#8200"
        );
        assert_eq!(
            frame(NmtCommand::PreOperational, NmtTarget::Node(Node(127))).to_string(),
            "000#807F"
        );
    }
}
