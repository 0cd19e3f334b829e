"""Recover the roughness of the Cornell box's sphere from an image of it, with PyTorch's Adam."""
import sys

import torch

import pathgrad as pg
import pathgrad.torch as pgt

iterations = int(sys.argv[1]) if len(sys.argv) > 1 else 60
scene = pg.load("builtin:cornell-box", width=32, height=32)
name = "sphere.bsdf.alpha.value"
target = torch.from_numpy(pg.render(scene, {name: 0.2}, spp=256, seed=10**6))  # the "photograph"

alpha = torch.tensor([0.6], requires_grad=True)
optimizer = torch.optim.Adam([alpha], lr=0.03)
for it in range(iterations):
    optimizer.zero_grad()
    image = pgt.render(scene, {name: alpha}, spp=16, seed=it)  # a new seed each iteration
    loss = ((image - target) ** 2).mean()
    loss.backward()  # Path Replay Backpropagation, with the image gradient as its adjoint
    optimizer.step()
    with torch.no_grad():
        alpha.clamp_(0.01, 1.0)  # stay inside the parameter's bounds
    if it % 10 == 9:
        print(f"iteration {it + 1}: loss {loss.item():.5f}, alpha {alpha.item():.4f}")
print(f"recovered alpha {alpha.item():.3f} (true 0.2)")
