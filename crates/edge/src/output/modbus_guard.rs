//! The Modbus TCP server's own framing and request decoding: every request is checked before any
//! code that could panic on it sees it.
//!
//! tokio-modbus 0.17 panics on a write-multiple-coils request (FC15) whose quantity is larger than
//! eight times its byte count (`decode_packed_coils` indexes out of bounds; upstream
//! slowtec/tokio-modbus issue 298, open at the time of writing): the 14-byte ADU
//! `000100000008010f0000001001ff` killed a connection task, and the same PDU in an RTU frame kills
//! the RTU server. So neither server hands bytes to tokio-modbus's decoders: the TCP server reads
//! the MBAP header and the PDU itself ([`read_frame`]), the RTU server frames by function code and
//! CRC ([`rtu_split`]); both decode the eight function codes the register map serves with the
//! consistency checks of the Modbus application protocol v1.1b3 (quantity ranges, byte count =
//! quantity, PDU length = byte count) ([`decode_request`]) and answer inconsistent requests with
//! exception 03 (illegal data value) themselves. tokio-modbus only supplies the `Request`/`Response`
//! types and the client roles. Upstream, the fix is a length check in `decode_packed_coils` (issue
//! 298); once a fixed release is out, the checks here can stay as they are (they are the spec's).
//! Should any code on these paths still panic, the connection (or RTU) task ends alone: the
//! panic is counted (`counters`: modbus-task-panics) and logged at most once per 10 s.
//!
//! Framing rules (MBAP, Modbus messaging on TCP/IP v1.0b 3.1.3): protocol id 0; length = unit id +
//! PDU, 2..=254 bytes. A header breaking them cannot be answered (the frame boundary is lost): the
//! connection is closed, as the guide allows.

use std::borrow::Cow;
use tokio::io::{AsyncRead, AsyncReadExt as _};
use tokio_modbus::{ExceptionCode, Request, Response};

/// Largest PDU (function code + data), bytes.
pub const MAX_PDU: usize = 253;

/// A framed TCP request (application data unit): MBAP transaction id and unit id, and the PDU.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Adu {
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
pub async fn read_frame<R: AsyncRead + Unpin>(r: &mut R, mut pdu: Vec<u8>) -> Result<Adu, FrameError> {
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
    Ok(Adu { transaction, unit: h[6], pdu })
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

/// The answer PDU to a request PDU, written to `out` (cleared first): `handle` is called with the
/// decoded request; a decoding problem or an exception from `handle` becomes an exception PDU
/// (function code | 0x80). Returns whether the answer is an exception.
pub fn answer_pdu(
    pdu: &[u8],
    handle: impl FnOnce(Request<'static>) -> Result<Response, ExceptionCode>,
    out: &mut Vec<u8>,
) -> bool {
    let fc = pdu.first().copied().unwrap_or(0);
    out.clear();
    let exception = match decode_request(pdu).and_then(handle) {
        Ok(rsp) => match encode_response(&rsp, out) {
            Some(()) => None,
            None => Some(ExceptionCode::ServerDeviceFailure),
        },
        Err(e) => Some(e),
    };
    if let Some(e) = exception {
        out.clear();
        out.extend_from_slice(&[fc | 0x80, u8::from(e)]);
    }
    exception.is_some()
}

/// The complete answer ADU (MBAP header + PDU) to a TCP `frame`, see [`answer_pdu`].
pub fn answer(
    frame: &Adu,
    handle: impl FnOnce(Request<'static>) -> Result<Response, ExceptionCode>,
    out: &mut Vec<u8>,
) -> bool {
    let mut pdu = Vec::with_capacity(MAX_PDU);
    let exception = answer_pdu(&frame.pdu, handle, &mut pdu);
    out.clear();
    push_header(out, frame.transaction, frame.unit, pdu.len());
    out.extend_from_slice(&pdu);
    exception
}

/// Modbus RTU CRC-16 (polynomial 0xA001, initial 0xFFFF), in wire order (low byte first).
pub fn crc16(data: &[u8]) -> [u8; 2] {
    let mut crc: u16 = 0xFFFF;
    for &b in data {
        crc ^= u16::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 { (crc >> 1) ^ 0xA001 } else { crc >> 1 };
        }
    }
    crc.to_le_bytes()
}

/// Whether `adu` (address, PDU, CRC) ends with the right CRC.
pub fn crc_ok(adu: &[u8]) -> bool {
    adu.len() >= 4 && crc16(&adu[..adu.len() - 2]) == [adu[adu.len() - 2], adu[adu.len() - 1]]
}

/// What the start of an RTU receive buffer holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RtuSplit {
    /// A complete request with a good CRC, this many bytes long.
    Frame(usize),
    /// Not enough bytes yet to tell (or a function code whose length only the silence after it
    /// tells).
    NeedMore,
    /// The first byte cannot start a frame (bad CRC at the length its function code implies):
    /// drop it and look again.
    Skip,
}

/// Frames RTU requests by the length their function code implies (as tokio-modbus does), checking
/// the CRC: FC01-06 are 8 bytes, FC15/16 9 + their byte count. Never indexes past `buf`.
pub fn rtu_split(buf: &[u8]) -> RtuSplit {
    if buf.len() < 2 {
        return RtuSplit::NeedMore;
    }
    let need = match buf[1] {
        0x01..=0x06 => 8,
        0x0F | 0x10 => match buf.get(6) {
            Some(&count) => 9 + usize::from(count),
            None => return RtuSplit::NeedMore,
        },
        _ => return RtuSplit::NeedMore,
    };
    match buf.get(..need) {
        None => RtuSplit::NeedMore,
        Some(adu) if crc_ok(adu) => RtuSplit::Frame(need),
        Some(_) => RtuSplit::Skip,
    }
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

    #[test]
    fn rtu_frames_split_by_function_code_and_crc() {
        let mut f = hex("050f0000001001ff");
        f.extend_from_slice(&crc16(&f));
        assert_eq!(rtu_split(&f), RtuSplit::Frame(f.len()));
        assert_eq!(rtu_split(&f[..6]), RtuSplit::NeedMore);
        let mut read = hex("0504000c0001");
        read.extend_from_slice(&crc16(&read));
        assert_eq!(crc16(&hex("010300000001")), [0x84, 0x0A], "the textbook example");
        let mut two = [hex("ff"), read.clone()].concat();
        assert_eq!(rtu_split(&two), RtuSplit::Skip, "noise before a frame");
        two.remove(0);
        assert_eq!(rtu_split(&two), RtuSplit::Frame(8));
        assert_eq!(rtu_split(&hex("052b0e01")), RtuSplit::NeedMore, "unknown length: the gap decides");
    }

    #[tokio::test]
    async fn a_bad_header_is_not_framed() {
        for adu in ["000100010006010400000001", "000100000001", "0001000000ff01"] {
            let r = read_frame(&mut hex(adu).as_slice(), Vec::new()).await;
            assert!(r.is_err(), "{adu}: {r:?}");
        }
    }
}
