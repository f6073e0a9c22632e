"""The spec file drives decoding: edit the TOML, decoding follows with no Python edit."""

from __future__ import annotations

import os
import re
from pathlib import Path

import independent
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from radar_io.decoding.decoders import FrameDecoder, decode_bytes
from radar_io.encoding.rdr1 import FrameEncoder
from radar_io.errors import SpecError
from radar_io.wirespec.frame import eval_number, load_spec, spec_dir

SPEC_TEXT = (spec_dir() / "rdr1.toml").read_text()


def edited(tmp_path: Path, *subs: tuple[str, str]) -> Path:
    text = SPEC_TEXT
    for old, new in subs:
        assert re.search(old, text, flags=re.S), old
        text = re.sub(old, new, text, count=1, flags=re.S)
    p = tmp_path / "rdr1.toml"
    p.write_text(text)
    return p


def both(spec, fr: bytes) -> tuple[dict, dict]:
    b = decode_bytes(fr, spec=spec)
    return FrameDecoder(spec).decode(fr), {c: b[c][0].item() for c in b.columns}


def test_changing_an_lsb_changes_both_decoders(tmp_path):
    spec = load_spec(edited(tmp_path, (r'(name = "sr".*?lsb = )1\.0', r'\g<1>0.5')))
    per, bat = both(spec, independent.frame(sr=1000, sts=5))
    assert per["sr_m"] == bat["sr_m"] == 500.0
    assert per["sr_c_m"] == bat["sr_c_m"] == 500.0  # DSR word 0x800 is 0 m
    spec = load_spec(edited(tmp_path, (r'(name = "daz".*?lsb = )"1\.0 \* 2\*\*-11"', r'\g<1>"2 * 2**-11"')))
    per, bat = both(spec, independent.frame(daz=0x800 + 512))
    assert per["daz_deg"] == bat["daz_deg"] == 0.5


def test_moving_a_status_bit_changes_both_decoders(tmp_path):
    fr = independent.frame(sts=0x0002)  # only B14 set
    default = load_spec()
    assert both(default, fr)[0]["go"] == 0
    spec = load_spec(edited(tmp_path, (r'(name = "go"\nbit = )15', r"\g<1>14")))
    per, bat = both(spec, fr)
    assert per["go"] == bat["go"] == 1
    spec = load_spec(edited(tmp_path, (r'bit_numbering = "msb0"', 'bit_numbering = "lsb0"')))
    # lsb0: "bit 15" is now the MSB (0x8000), which is where SYNC (B0 msb0) lives
    per, bat = both(spec, independent.frame(sts=0x8000))
    assert per["go"] == bat["go"] == 1


def test_changing_an_encoding_changes_both_decoders(tmp_path):
    spec = load_spec(edited(tmp_path, (r'(name = "el".*?encoding = )"twos_complement"', r'\g<1>"unsigned"')))
    per, bat = both(spec, independent.frame(el=-1))
    assert per["el_deg"] == bat["el_deg"] == 65535 * 180 / 32768
    assert independent.decode(independent.frame(el=-1))["el_deg"] == -180 / 32768


def test_changing_the_bit_width_changes_plausibility(tmp_path):
    spec = load_spec(edited(tmp_path, (r'(name = "dsr".*?bits = )12', r"\g<1>13")))
    fr = independent.frame(dsr=0x1800)  # bit 12 set: implausible for 12 bits, fine for 13
    assert decode_bytes(fr).stats["implausible"] == 1
    b = decode_bytes(fr, spec=spec)
    assert b.stats["frames"] == 1 and b["dsr_m"][0] == (0x1800 - 4096) * 50 / 2048


def test_encoder_follows_the_spec_too(tmp_path):
    spec = load_spec(edited(tmp_path, (r"sync_word = 0xEB90", "sync_word = 0x1234")))
    fr = FrameEncoder(spec).encode_raw({"seq": 1, "tod": 2, "sr": 3, "dsr": 4, "el": 5, "del": 6,
                                        "az": 7, "daz": 8, "sts": 9})
    assert fr[:2] == b"\x12\x34"
    assert decode_bytes(fr, spec=spec)["sr_m"][0] == 3.0
    assert decode_bytes(fr).stats["frames"] == 0


@pytest.mark.parametrize("sub,message", [
    ((r"check = 0x29B1", "check = 0x1234"), "check value"),
    ((r'(name = "sr".*?offset = )8', r"\g<1>10"), "field 'dsr': bytes 10..11 overlap field 'sr'"),
    ((r'(name = "sr".*?encoding = )"unsigned"', r'\g<1>"bcd"'), "encoding"),
    ((r'(name = "el".*?lsb = )"180 \* 2\*\*-15"', r'\g<1>"__import__(1)"'), "arithmetic"),
    ((r'name = "tod"', 'name = "time"'), "missing required field"),
    ((r'(name = "go"\nbit = )15', r"\g<1>16"), "outside"),
    ((r'(name = "rx_good"\nbit = )13', r"\g<1>15"), "overlaps"),
    ((r"\[frame\]", "[frame"), "not valid TOML"),
])
def test_bad_spec_files_give_a_clear_error(tmp_path, sub, message):
    with pytest.raises(SpecError, match=message):
        load_spec(edited(tmp_path, sub))


@pytest.mark.parametrize("sub,message", [
    # unknown key, in each table: a typo is refused, never silently ignored
    ((r"(\[frame\]\n)", r"\g<1>lenght_bytes = 24\n"), r"\[frame\]: unknown key 'lenght_bytes'"),
    ((r"(\[crc\]\n)", r"\g<1>refin = false\n"), r"\[crc\]: unknown key 'refin'"),
    ((r'(name = "sr"\n)', r"\g<1>scale = 2\n"), r"field 'sr': unknown key 'scale'"),
    ((r'(name = "go"\n)', r"\g<1>mask = 1\n"), r"flag 'go': unknown key 'mask'"),
    ((r"(\[status\]\n)", r"\g<1>numbering = 'msb0'\n"), r"\[status\]: unknown key 'numbering'"),
    ((r"^", "version = 2\n"), r"rdr1.toml: unknown key 'version'"),
    # wrong type of a required and of an optional key
    ((r"length_bytes = 24", 'length_bytes = "24"'), r"\[frame\]: key 'length_bytes' has the wrong type"),
    ((r'(name = "dsr".*?bits = )12', r'\g<1>"12"'), r"field 'dsr': key 'bits' has the wrong type"),
    ((r'(name = "tod".*?max_raw = )863_999_999', r"\g<1>8.6e8"),
     r"field 'tod': key 'max_raw' has the wrong type"),
    ((r'(name = "az".*?unit = )"deg"', r"\g<1>1"), r"field 'az': key 'unit' has the wrong type"),
    ((r'(name = "servo_bw"\nbit = 2.*?width = )2', r"\g<1>true"),
     r"flag 'servo_bw': key 'width' has the wrong type"),
    ((r"reflect_in = false", "reflect_in = 0"), r"\[crc\]: key 'reflect_in' has the wrong type"),
    # missing field / key
    ((r'(name = "daz"\noffset = 18\n)size = 2\n', r"\g<1>"), r"field 'daz': missing key 'size'"),
    ((r"poly = 0x1021\n", ""), r"\[crc\]: missing key 'poly'"),
    # overlapping fields name both
    ((r'(name = "az"\noffset = )16', r"\g<1>14"), r"field 'az': bytes 14..15 overlap field 'del'"),
    ((r'(name = "sts"\noffset = )20', r"\g<1>21"), r"field 'sts': bytes 21..22 overlap the CRC"),
    ((r'(name = "seq"\noffset = )2', r"\g<1>1"), r"field 'seq': bytes 1..2 overlap the sync word"),
    # byte order: the framers read big-endian words only
    ((r'byte_order = "big"', 'byte_order = "little"'), r"\[frame\]: byte_order = 'little' is not supported"),
])
def test_strict_spec_validation_names_file_and_field(tmp_path, sub, message):
    with pytest.raises(SpecError, match=message) as e:
        load_spec(edited(tmp_path, sub))
    line = str(e.value)
    assert "\n" not in line and str(tmp_path / "rdr1.toml") in line


def test_missing_spec_file(tmp_path):
    with pytest.raises(SpecError, match="not found"):
        load_spec(tmp_path / "nope.toml")


def test_lsb_expressions():
    assert eval_number("180 * 2**-15", what="x") == 180 / 32768
    assert eval_number("-(50/2048)", what="x") == -50 / 2048
    for bad in ("os.system('x')", "1 if 1 else 2", "", True):
        with pytest.raises(SpecError):
            eval_number(bad, what="x")


def test_spec_declares_the_source_bit_numbering(spec):
    masks = {f.name: f.mask for f in spec.flags}
    assert masks == {"sync": 0x8000, "auto": 0x4000, "servo_bw": 0x3000, "rx_good": 0x0004,
                     "go": 0x0001}
    lsb = {f.name: f.lsb for f in spec.fields}
    assert lsb["dsr"] == 50 * 2**-11 and lsb["el"] == 180 * 2**-15 and lsb["tod"] == 1e-4
    assert np.isclose(spec.field("tod").max_raw, 863_999_999)


_LINES = SPEC_TEXT.splitlines()
_VALUE_LINES = [i for i, ln in enumerate(_LINES) if "=" in ln and not ln.lstrip().startswith("#")]
_JUNK = ["0", "-1", "1e999", "true", '"x"', '""', "[]", "[1, 2]", "{}", "0xFFFFFFFFFF", "2.5",
         '"1/0"', '"2**2**2**2**2"', "65536", "-0.0", '"big"', '"little"']


@pytest.mark.slow
@settings(max_examples=int(os.environ.get("RADAR_IO_FUZZ_EXAMPLES", "300")), deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.tuples(st.sampled_from(_VALUE_LINES), st.sampled_from([*_JUNK, "<drop>"])),
                min_size=1, max_size=3))
def test_mutated_spec_files_load_or_give_one_line(tmp_path, edits):
    """Any value swapped for junk, or any line dropped: a spec, or one SpecError line naming the file."""
    lines = list(_LINES)
    for i, junk in edits:
        key = lines[i].split("=", 1)[0]
        lines[i] = "" if junk == "<drop>" else f"{key}= {junk}"
    p = tmp_path / "mutated.toml"
    p.write_text("\n".join(lines) + "\n")
    try:
        spec = load_spec(p)
    except SpecError as exc:
        msg = str(exc)
        assert "\n" not in msg and str(p) in msg, msg
    else:
        assert spec.length == 24 and spec.byte_order == "big"
