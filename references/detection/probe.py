"""Steps per second of each detector on this machine (batch B), for planning a training budget."""
import sys, time, torch
from gpr3d.detection.data import WindowDataset, collate
from gpr3d.detection.models import build_model, MODELS
from gpr3d.simulation.surveys import survey_sample

dev = sys.argv[1] if len(sys.argv) > 1 else "cpu"
B = int(sys.argv[2]) if len(sys.argv) > 2 else 16
W = int(sys.argv[3]) if len(sys.argv) > 3 else 0
ds = WindowDataset(lambda i: survey_sample(1000, i), 400)
t = time.perf_counter()
dl = torch.utils.data.DataLoader(ds, batch_size=B, collate_fn=collate, num_workers=W)
batches = [b for _, b in zip(range(8), dl)]
print(f"data: {8 * B / (time.perf_counter() - t):.1f} windows/s with {W} workers", flush=True)
for name in MODELS:
    m = build_model(name).to(dev).train()
    opt = torch.optim.AdamW(m.parameters(), 1e-4)
    for k in range(12):
        if k == 4:
            if dev.startswith("cuda"): torch.cuda.synchronize()
            t = time.perf_counter()
        ims, tg = batches[k % 8]
        loss = sum(m([i.to(dev) for i in ims], [{a: v.to(dev) for a, v in x.items()} for x in tg]).values())
        opt.zero_grad(); loss.backward(); opt.step()
    if dev.startswith("cuda"): torch.cuda.synchronize()
    print(f"{name:16s} {(time.perf_counter() - t) / 8 * 1000:7.1f} ms/step (batch {B})", flush=True)
