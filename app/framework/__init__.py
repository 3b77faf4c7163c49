"""The paper's Fig. 1, one module per block.

- ``encoder``        CONV_XF: tactile sample -> feature vector f_ext
- ``novelty``        ND(x): GMM weighted log-likelihood against sigma_nov
- ``classifiers``    FC_Y (known objects) and FC_Z (novel objects)
- ``generator``      G: attribute vector (+ noise) -> synthetic feature f_gen
- ``discriminator``  D: real or synthetic feature
- ``adversarial``    Algorithm 1 (G through frozen FC_Y) and Algorithm 2 (G against D)
- ``synthesis``      GEN-F and NEIGHB-F training sets for FC_Z
- ``one_shot``       Sect. IV-F: a real sample's k nearest real features train FC_Z
- ``recognizer``     the interface every recognition method implements
- ``paper``          the paper's pipeline wired together
- ``bundle``         the versioned model artifact
"""
