"""itr_fft package."""
