"""Make tests/data/rdr1_golden.npz with main's decoder (commit ec9980f)."""
import json
import sys
from pathlib import Path

import numpy as np

from radar_io.benchmarks.core import corrupt_bytes
from radar_io.decoding.biases import Calibration
from radar_io.decoding.decoders import decode_bytes
from radar_io.simulation.radar import RadarSimulator, SimConfig
from radar_io.wirespec.frame import load_spec

spec = load_spec()
sim = RadarSimulator(config=SimConfig(seed=23, tod_start_s=36000.0, loop=True, ng_per_min=600), spec=spec)
clean, _ = sim.generate(6000)
vec = json.loads((Path(__file__).parent / "rdr1_vectors.json").read_text())
vframes = b"".join(bytes.fromhex(v["hex"]) for v in vec["frames"])
data = vframes + clean
damaged = corrupt_bytes(data, 0.01, seed=3)
cal = Calibration(dsr_m=2.5, del_deg=-0.013, daz_deg=0.021)
out = {"input_clean": np.frombuffer(data, np.uint8), "input_damaged": np.frombuffer(damaged, np.uint8)}
for name, d in (("clean", data), ("damaged", damaged)):
    for cname, c in (("nocal", None), ("cal", cal)):
        b = decode_bytes(d, c)
        for col in b.columns:
            out[f"{name}/{cname}/{col}"] = b[col]
        out[f"{name}/{cname}/stats"] = np.array(json.dumps(b.stats))
        out[f"{name}/{cname}/columns"] = np.array(json.dumps(list(b.columns)))
np.savez_compressed(sys.argv[1], **out)
print({k: v.shape for k, v in out.items() if "stats" in k}, len(data))
