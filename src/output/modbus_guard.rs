//! The Modbus TCP server's own framing and request decoding: every request is checked before any
//! code that could panic on it sees it.
//!
//! tokio-modbus 0.17 panics on a write-multiple-coils request (FC15) whose quantity is larger than
//! eight times its byte count (`decode_packed_coils` indexes out of bounds; upstream
//! slowtec/tokio-modbus issue 298, open at the time of writing): the 14-byte ADU
//! `000100000008010f0000001001ff` killed a connection task. The TCP server therefore no longer
//! hands bytes to tokio-modbus at all: it reads the MBAP header and the PDU itself
//! ([`read_frame`]), decodes the eight function codes the register map serves with the consistency
//! checks of the Modbus application protocol v1.1b3 (quantity ranges, byte count = quantity,
//! PDU length = byte count) ([`decode_request`]) and answers inconsistent requests with exception
//! 03 (illegal data value) itself. tokio-modbus only supplies the `Request`/`Response` types and
//! the RTU server; the RTU server task is restarted (and its panic logged, throttled) if it ever
//! panics.
//!
//! Framing rules (MBAP, Modbus messaging on TCP/IP v1.0b 3.1.3): protocol id 0; length = unit id +
//! PDU, 2..=254 bytes. A header breaking them cannot be answered (the frame boundary is lost): the
//! connection is closed, as the guide allows.

use std::borrow::Cow;
use tokio::io::{AsyncRead, AsyncReadExt as _};
use tokio_modbus::{ExceptionCode, Request, Response};

/// Largest PDU (function code + data), bytes.
pub const MAX_PDU: usize = 253;

/// A framed request: MBAP transaction id and unit id, and the PDU.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Frame {
    /// Transaction id (echoed).
    pub transaction: u16,
    /// Unit id (echoed).
    pub unit: u8,
    /// Function code and data.
    pub pdu: Vec<u8>,
}

/// Why a connection's byte stream cannot be framed.
#[derive(Debug, thiserror::Error)]
pub enum FrameError {
    /// The peer closed the connection or the stream failed (idle timeout, eviction, reset).
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// The MBAP header breaks the framing rules.
    #[error("bad MBAP header (protocol id {protocol}, length {length})")]
    Header {
        /// Protocol id (must be 0).
        protocol: u16,
        /// Length field (must be 2..=254).
        length: u16,
    },
}

/// Reads one MBAP-framed request from `r`. `pdu` is reused as the frame's buffer.
pub async fn read_frame<R: AsyncRead + Unpin>(r: &mut R, mut pdu: Vec<u8>) -> Result<Frame, FrameError> {
    let mut h = [0u8; 7];
    r.read_exact(&mut h).await?;
    let transaction = u16::from_be_bytes([h[0], h[1]]);
    let protocol = u16::from_be_bytes([h[2], h[3]]);
    let length = u16::from_be_bytes([h[4], h[5]]);
    if protocol != 0 || !(2..=254).contains(&length) {
        return Err(FrameError::Header { protocol, length });
    }
    pdu.clear();
    pdu.resize(usize::from(length) - 1, 0);
    r.read_exact(&mut pdu).await?;
    Ok(Frame { transaction, unit: h[6], pdu })
}

fn word(b: &[u8], i: usize) -> u16 {
    u16::from_be_bytes([b[i], b[i + 1]])
}

/// Decodes a request PDU with every consistency check done before anything is indexed. Function
/// codes other than 1, 2, 3, 4, 5, 6, 15 and 16 are [`ExceptionCode::IllegalFunction`]; a wrong
/// length, quantity or byte count is [`ExceptionCode::IllegalDataValue`] (exception 03). Never
/// panics, whatever the bytes.
pub fn decode_request(pdu: &[u8]) -> Result<Request<'static>, ExceptionCode> {
    let Some(&fc) = pdu.first() else { return Err(ExceptionCode::IllegalFunction) };
    let bad = Err(ExceptionCode::IllegalDataValue);
    match fc {
        0x01..=0x06 => {
            if pdu.len() != 5 {
                return bad;
            }
            let (a, n) = (word(pdu, 1), word(pdu, 3));
            match fc {
                0x01 | 0x02 if !(1..=2000).contains(&n) => bad,
                0x03 | 0x04 if !(1..=125).contains(&n) => bad,
                0x01 => Ok(Request::ReadCoils(a, n)),
                0x02 => Ok(Request::ReadDiscreteInputs(a, n)),
                0x03 => Ok(Request::ReadHoldingRegisters(a, n)),
                0x04 => Ok(Request::ReadInputRegisters(a, n)),
                0x05 => match n {
                    0xFF00 => Ok(Request::WriteSingleCoil(a, true)),
                    0x0000 => Ok(Request::WriteSingleCoil(a, false)),
                    _ => bad,
                },
                _ => Ok(Request::WriteSingleRegister(a, n)),
            }
        }
        0x0F | 0x10 => {
            if pdu.len() < 6 {
                return bad;
            }
            let (a, n, count) = (word(pdu, 1), word(pdu, 3), usize::from(pdu[5]));
            let data = &pdu[6..];
            if data.len() != count {
                return bad;
            }
            if fc == 0x0F {
                if !(1..=0x07B0).contains(&n) || count != usize::from(n).div_ceil(8) {
                    return bad;
                }
                let coils = (0..usize::from(n)).map(|i| data[i / 8] & (1 << (i % 8)) != 0).collect::<Vec<_>>();
                Ok(Request::WriteMultipleCoils(a, Cow::Owned(coils)))
            } else {
                if !(1..=123).contains(&n) || count != 2 * usize::from(n) {
                    return bad;
                }
                let words = data.chunks_exact(2).map(|c| u16::from_be_bytes([c[0], c[1]])).collect::<Vec<_>>();
                Ok(Request::WriteMultipleRegisters(a, Cow::Owned(words)))
            }
        }
        _ => Err(ExceptionCode::IllegalFunction),
    }
}

fn push_word(out: &mut Vec<u8>, w: u16) {
    out.extend_from_slice(&w.to_be_bytes());
}

/// Appends the PDU of `rsp` to `out`; `None` for a response this server never produces (the
/// caller answers exception 04 instead).
pub fn encode_response(rsp: &Response, out: &mut Vec<u8>) -> Option<()> {
    match rsp {
        Response::ReadCoils(bits) | Response::ReadDiscreteInputs(bits) => {
            let fc = if matches!(rsp, Response::ReadCoils(_)) { 0x01 } else { 0x02 };
            let n = u8::try_from(bits.len().div_ceil(8)).ok()?;
            out.extend_from_slice(&[fc, n]);
            for chunk in bits.chunks(8) {
                out.push(chunk.iter().enumerate().fold(0u8, |b, (i, &on)| b | (u8::from(on) << i)));
            }
        }
        Response::ReadHoldingRegisters(words) | Response::ReadInputRegisters(words) => {
            let fc = if matches!(rsp, Response::ReadHoldingRegisters(_)) { 0x03 } else { 0x04 };
            out.extend_from_slice(&[fc, u8::try_from(words.len() * 2).ok()?]);
            for &w in words {
                push_word(out, w);
            }
        }
        Response::WriteSingleCoil(a, on) => {
            out.push(0x05);
            push_word(out, *a);
            push_word(out, if *on { 0xFF00 } else { 0 });
        }
        Response::WriteSingleRegister(a, v) => {
            out.push(0x06);
            push_word(out, *a);
            push_word(out, *v);
        }
        Response::WriteMultipleCoils(a, n) | Response::WriteMultipleRegisters(a, n) => {
            out.push(if matches!(rsp, Response::WriteMultipleCoils(..)) { 0x0F } else { 0x10 });
            push_word(out, *a);
            push_word(out, *n);
        }
        _ => return None,
    }
    Some(())
}

/// Appends an MBAP header for a PDU of `pdu_len` bytes.
pub fn push_header(out: &mut Vec<u8>, transaction: u16, unit: u8, pdu_len: usize) {
    push_word(out, transaction);
    push_word(out, 0);
    push_word(out, u16::try_from(pdu_len + 1).unwrap_or(u16::MAX));
    out.push(unit);
}

/// The complete answer ADU to `frame`: `handle` is called with the decoded request; a decoding
/// problem or an exception from `handle` becomes an exception response (function code | 0x80).
/// Returns whether the answer is an exception.
pub fn answer(
    frame: &Frame,
    handle: impl FnOnce(Request<'static>) -> Result<Response, ExceptionCode>,
    out: &mut Vec<u8>,
) -> bool {
    let fc = frame.pdu.first().copied().unwrap_or(0);
    let mut pdu = Vec::with_capacity(MAX_PDU);
    let result = decode_request(&frame.pdu).and_then(handle);
    let exception = match result {
        Ok(rsp) => match encode_response(&rsp, &mut pdu) {
            Some(()) => None,
            None => Some(ExceptionCode::ServerDeviceFailure),
        },
        Err(e) => Some(e),
    };
    if let Some(e) = exception {
        pdu.clear();
        pdu.extend_from_slice(&[fc | 0x80, u8::from(e)]);
    }
    out.clear();
    push_header(out, frame.transaction, frame.unit, pdu.len());
    out.extend_from_slice(&pdu);
    exception.is_some()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hex(s: &str) -> Vec<u8> {
        (0..s.len()).step_by(2).map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap_or(0)).collect()
    }

    #[tokio::test]
    async fn the_frame_of_upstream_issue_298_gets_exception_03() {
        let adu = hex("000100000008010f0000001001ff");
        let frame = read_frame(&mut adu.as_slice(), Vec::new()).await.expect("framed");
        assert_eq!(frame.pdu, hex("0f0000001001ff"));
        let mut out = Vec::new();
        assert!(answer(&frame, |_| panic!("must not reach the handler"), &mut out));
        assert_eq!(out, hex("000100000003018f03"));
    }

    #[test]
    fn consistent_requests_decode() {
        assert_eq!(decode_request(&hex("0400000018")), Ok(Request::ReadInputRegisters(0, 24)));
        assert_eq!(
            decode_request(&hex("0f0000000a0201ff"))
                .map(|r| matches!(r, Request::WriteMultipleCoils(0, c) if c.len() == 10)),
            Ok(true)
        );
        assert_eq!(
            decode_request(&hex("100064000204000100ff")),
            Ok(Request::WriteMultipleRegisters(100, Cow::Owned(vec![1, 255])))
        );
        assert_eq!(decode_request(&hex("0500000001")), Err(ExceptionCode::IllegalDataValue), "FC05 value");
        assert_eq!(decode_request(&hex("040000007e")), Err(ExceptionCode::IllegalDataValue), "126 registers");
        assert_eq!(decode_request(&hex("0400000000")), Err(ExceptionCode::IllegalDataValue), "0 registers");
        assert_eq!(decode_request(&hex("04000001")), Err(ExceptionCode::IllegalDataValue), "short");
        assert_eq!(decode_request(&hex("1000640002030001ff")), Err(ExceptionCode::IllegalDataValue), "byte count");
        assert_eq!(decode_request(&hex("2b0e0100")), Err(ExceptionCode::IllegalFunction));
        assert_eq!(decode_request(&[]), Err(ExceptionCode::IllegalFunction));
    }

    #[tokio::test]
    async fn a_bad_header_is_not_framed() {
        for adu in ["000100010006010400000001", "000100000001", "0001000000ff01"] {
            let r = read_frame(&mut hex(adu).as_slice(), Vec::new()).await;
            assert!(r.is_err(), "{adu}: {r:?}");
        }
    }
}
