"""The runtime of the processes vibr runs in, set before any work: compiler flags of the
kernels (:mod:`.jit`), glibc's malloc thresholds (:mod:`.malloc`), the viewer's render threads
(:mod:`.threads`), pycolmap imported without glog's signal handlers (:mod:`.pycolmap`), the
memory available (:mod:`.memory`), and the files vibr writes: atomic outputs
(:mod:`.atomic`) and resumable checkpoints keyed by vibr's code (:mod:`.checkpoint`).

Nothing here knows of scenes, images or renders; every other package may import it.
"""
