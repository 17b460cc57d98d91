"""Where each variable of the navigation manifold sits in X (navigation.py explains them):
p (3) | tau (3) | d_1..d_6 (18) | l (6) | f0 (6) | G (36) | g (6) | s (6) | t (6).
Its own module so that the numpy model and the compiled kernel share it without importing
each other."""

I_P, I_TAU, I_D, I_L, I_F, I_V, I_G, I_S, I_T = 0, 3, 6, 24, 30, 36, 72, 78, 84
N_VARS = 90
N_EQS = 84
