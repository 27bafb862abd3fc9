"""Proving a design and its implementations: the float64 reference law, the bit-exact float32 model of the C, the
one-step (resynchronised) check, replay of recorded samples, the design-time float32 fidelity check, the closed-loop
twin and the closed-loop simulation, all around one sampled plant model."""
