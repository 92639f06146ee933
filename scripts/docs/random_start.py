import random, math
rng = random.Random(44)
while True:
    pts=[]
    while len(pts)<6:
        p=(round(rng.uniform(-150,450),1), round(rng.uniform(-150,450),1))
        if all(math.dist(p,q)>=100 for q in pts): pts.append(p)
    a,b,c=pts[:3]
    ex=(b[0]-a[0],b[1]-a[1]); ac=(c[0]-a[0],c[1]-a[1])
    cross=ex[0]*ac[1]-ex[1]*ac[0]
    if cross/math.hypot(*ex)/math.hypot(*ac)>=0.2: break
print([list(p) for p in pts])
print("height", round(rng.uniform(-100,300),1), "tilt", round(rng.uniform(-30,30),1), "pool", rng.randint(151,200), "eps", round(rng.uniform(0.005,0.03),4))
