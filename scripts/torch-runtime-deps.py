"""Print the run-time requirements of the installed torch, less those only a GPU uses.

PyPI has no CPU-only torch wheel for Linux x86_64: its torch links the CUDA libraries (shipped
as nvidia-* wheels) and pulls in triton, the GPU kernel compiler (~1 GB), and cuda-bindings.
The libraries must be there for `import torch` to succeed; triton and cuda-bindings need not.
Installing torch with --no-deps and then these requirements saves about 1 GB and a minute.
"""

import importlib.metadata as md

GPU_ONLY = {"triton", "cuda-bindings"}

for req in md.requires("torch") or []:
    spec, _, marker = req.partition(";")
    name = spec.split("[")[0]
    for sep in "<>=!~ ":
        name = name.split(sep)[0]
    if "extra ==" in marker or name.strip().lower() in GPU_ONLY:
        continue
    print(spec.strip())
