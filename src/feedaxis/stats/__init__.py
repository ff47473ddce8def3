"""Statistical building blocks of the diagnosis, independent of any model or fit: the tests
and the family-wise policy (:mod:`.judge`), the noise models a verdict names
(:mod:`.noise`), tests under serially correlated noise (:mod:`.coloured`), the spatial
spectrum (:mod:`.spectrum`) and how a statistic is written (:mod:`.wording`)."""
