//! What `board::init` and the link leave behind (no jumpers): the laser gate off,
//! the hot code in ITCM.

#[embedded_test::tests(default_timeout = 10)]
mod tests {
    use embassy_stm32::pac;
    use shared::hans::frame::Frame;
    use shared::hans::rx::{HansRx, Mode as HansMode};
    use xy_bridge::board::{self, Board};

    #[init]
    fn init() -> Board {
        board::init()
    }

    /// The laser gate after `board::init` (no jumpers): PF13 must be an output
    /// (MODER), written low (ODR) and low at the pad (IDR: the input stage reads
    /// the pin in output mode too), and `Board::laser_gate` must say so. The test
    /// never drives the gate high: a board with its transceivers fitted may have a
    /// laser behind it.
    #[test]
    fn laser_gate_is_off_after_init(board: Board) {
        use pac::gpio::vals::{Idr, Moder, Odr};
        let pin = board::LASER_GATE_PIN;
        let port = pac::GPIOF;
        assert_eq!(
            port.moder().read().moder(pin),
            Moder::OUTPUT,
            "PF13 not driven"
        );
        assert_eq!(port.odr().read().odr(pin), Odr::LOW, "PF13 written high");
        assert_eq!(port.idr().read().idr(pin), Idr::LOW, "PF13 high at the pad");
        assert!(board.laser_gate.is_set_low());
    }

    /// Hot code in ITCM (no jumpers; firmware/tcm.rs, `memory.x`). `__pre_init`
    /// copied `.itcm` from flash before `main`: the running image must equal its load
    /// image byte for byte, `hans::Frame::decode` (a per-frame `shared::hans::frame`
    /// function, which the linker script puts there) must have its address in
    /// `.itcm`, not in flash, and calls through that address must run: a frame's
    /// pattern decodes to the frame, the pattern with one bit flipped is refused.
    /// `HansRx::new`, a constructor, is kept in flash as cold code (`.flash_cold`).
    #[test]
    fn itcm_holds_the_hot_code(_board: Board) {
        let itcm = xy_bridge::tcm::itcm();
        assert!(itcm.start > 0 && itcm.start < itcm.end && itcm.end <= 0x1_0000);
        let (run, load) = xy_bridge::tcm::itcm_load_image();
        let differ = run.iter().zip(load).filter(|(a, b)| a != b).count();
        assert_eq!(differ, 0, "ITCM bytes that differ from the flash image");
        let decode: fn(u128) -> Result<Frame, _> = Frame::decode;
        let addr = decode as usize & !1;
        assert!(
            itcm.contains(&addr),
            "hans::Frame::decode at {:#x}, not in ITCM",
            addr
        );
        let frame = Frame::new(0x1_2345, 0xF_EDCB, 0x5_A5A5).unwrap();
        assert_eq!(decode(frame.encode()), Ok(frame));
        assert!(decode(frame.encode() ^ 1 << 60).is_err());
        let new: fn(u32, HansMode) -> Result<HansRx, _> = HansRx::new;
        assert!(
            !itcm.contains(&(new as usize & !1)),
            "HansRx::new (cold) in ITCM"
        );
    }
}
