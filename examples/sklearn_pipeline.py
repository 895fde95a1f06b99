"""R-PointHop inside scikit-learn: compress descriptors with PCA, cluster the points.

Points with similar local geometry end up in the same cluster, wherever they are and
however the shape is turned.
"""

import numpy as np
from scipy.spatial.transform import Rotation
from sklearn.cluster import KMeans
from sklearn.decomposition import PCA
from sklearn.pipeline import make_pipeline

from o3d_rpointhop import RPointHopTransformer
from o3d_rpointhop.datasets import make_object

cloud = make_object(2048, shape_seed=7)
pipe = make_pipeline(RPointHopTransformer(random_state=0), PCA(16, random_state=0))
compact = pipe.fit_transform(cloud)  # fitted on this cloud's own points
print("compressed descriptors:", compact.shape)

labels = KMeans(6, n_init=4, random_state=0).fit_predict(compact)
rotation = Rotation.random(random_state=1).as_matrix()
rotated = cloud @ rotation.T
same = KMeans(6, n_init=4, random_state=0).fit_predict(pipe.transform(rotated))
# The clustering of the rotated cloud is the same partition (up to label names).
agree = np.mean([np.bincount(same[labels == k]).max() / np.sum(labels == k) for k in range(6)])
print(f"clusters agree after a rotation: {agree:.1%}")
