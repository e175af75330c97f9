"""Recovery: the image's consistency and the health state, the second opinion and challenger from
the encoders, which bias jumps an image can test.
"""
